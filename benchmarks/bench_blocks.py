"""Block-wise meshing benchmark (issue 27): throughput against the in-memory mesher, 1 vs
2 workers, and a big volume under a memory cap.

Run:  python benchmarks/bench_blocks.py [--n 256] [--big]

Every run is a ``swa-imesh mesh`` subprocess, so both paths pay the same: reading the
labels, meshing, checks, facet groups and writing (``.vtu`` in memory, ``.pvtu`` pieces
block-wise). Peak memory is that of the whole process tree (the command, the Dask
scheduler, nanny and worker processes), sampled every 0.2 s with psutil.

1. A brain-like ``n^3`` volume (``bench_mesh.brain_like``; background excluded) stored as
   Zarr in 128^3 chunks: the in-memory mesh, then block-wise with 1 and 2 workers at
   ``--memory 4GB``; seconds per million voxels, and the element counts (equal when the
   block is the in-memory root, else the difference of cutting leaves at block faces).
2. ``--big``: a brain-like 400 x 470 x 380 volume in 128^3 chunks, 2 workers at
   ``--memory 4GB``; its peak must stay under 10 GB. Heavy: run it alone, as
   ``flock /work/wt/heavy.lock python benchmarks/bench_blocks.py --big``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np


def brain_like_shape(shape, seed: int = 0) -> np.ndarray:
    """``bench_mesh.brain_like`` for any box: nested noisy shells, labels 0..5."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    axes = np.ogrid[tuple(slice(0, n) for n in shape)]
    semi = np.array([0.50, 0.44, 0.48]) * np.asarray(shape)
    r = np.zeros(shape, np.float32)
    for a, s, n in zip(axes, semi, shape):
        r += (((a + 0.5 - n / 2) / s) ** 2).astype(np.float32)
    np.sqrt(r, out=r)
    for cells, amp in ((4, 0.06), (16, 0.025), (64, 0.012)):
        coarse = rng.standard_normal((cells,) * 3).astype(np.float32)
        zoomed = ndimage.zoom(coarse, [n / cells for n in shape], order=1)
        r += amp * zoomed[tuple(slice(0, n) for n in shape)]
        del zoomed
    labels = (5 - np.digitize(r, [0.45, 0.62, 0.75, 0.82, 0.92])).astype(np.uint8)
    del r
    spots = rng.random(shape, dtype=np.float32) < 2e-4
    labels[spots] = np.minimum(labels[spots] + 1, 5)
    return labels


def write_zarr(labels: np.ndarray, path: Path, chunk: int = 128) -> None:
    import zarr

    z = zarr.open(str(path), mode="w", shape=labels.shape, chunks=(chunk,) * labels.ndim,
                  dtype=labels.dtype)
    z[:] = labels


def run_tree(cmd: list[str]) -> dict:
    """Run `cmd`; wall seconds, exit status and the peak RSS of its process tree."""
    import psutil

    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = [0]
    done = threading.Event()

    def sample():
        root = psutil.Process(proc.pid)
        while not done.is_set():
            try:
                procs = [root] + root.children(recursive=True)
                total = 0
                for p in procs:
                    try:
                        total += p.memory_info().rss
                    except psutil.Error:
                        pass
                peak[0] = max(peak[0], total)
            except psutil.Error:
                pass
            done.wait(0.2)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    out, err = proc.communicate()
    done.set()
    th.join()
    row = {"seconds": time.perf_counter() - t0, "rc": proc.returncode, "peak": peak[0]}
    if proc.returncode:
        row["error"] = err.strip().splitlines()[-1] if err.strip() else ""
    else:
        try:
            row["report"] = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            row["report"] = {}
    return row


def _elements(row: dict) -> int | None:
    r = row.get("report", {})
    return r.get("n_elements") or r.get("elements") or (r.get("mesh") or {}).get("n_elements")


def throughput(n: int, folder: Path) -> None:
    labels = brain_like_shape((n,) * 3)
    n_vox = labels.size
    np.save(folder / "lab.npy", labels)
    write_zarr(labels, folder / "lab.zarr")
    del labels
    exe = [sys.executable, "-m", "napari_swa_imesh.cli", "mesh"]
    rows = {"in-memory (.vtu)": run_tree(exe + [str(folder / "lab.npy"), "-o",
                                                str(folder / "mem.vtu"), "--exclude", "0",
                                                "--json"])}
    for w in (1, 2):
        rows[f"blocks, {w} worker(s)"] = run_tree(
            exe + [str(folder / "lab.zarr"), "-o", str(folder / f"b{w}.pvtu"), "--exclude",
                   "0", "--workers", str(w), "--memory", "4GB", "--json"])
    base = rows["in-memory (.vtu)"]["seconds"]
    print(f"brain-like {n}^3 ({n_vox / 1e6:.1f} M voxels), Zarr chunks 128^3, background "
          "excluded; indicative times on a shared 2-core machine")
    print(f"{'run':24s} {'s':>8s} {'s/Mvox':>8s} {'x in-mem':>9s} {'peak GB':>8s} "
          f"{'elements':>10s} {'block':>6s}")
    for name, row in rows.items():
        if row["rc"]:
            print(f"{name:24s} failed: {row.get('error')}")
            continue
        print(f"{name:24s} {row['seconds']:8.1f} {row['seconds'] / n_vox * 1e6:8.2f} "
              f"{row['seconds'] / base:9.2f} {row['peak'] / 2**30:8.2f} "
              f"{_elements(row) or 0:10d} {row['report'].get('block', '-')!s:>6s}")
    one, two = rows["blocks, 1 worker(s)"], rows["blocks, 2 worker(s)"]
    if not (one["rc"] or two["rc"]):
        print(f"speed-up 1 -> 2 workers: {one['seconds'] / two['seconds']:.2f}x "
              "(2 cores shared with other jobs)")


def big(folder: Path) -> None:
    shape = (400, 470, 380)
    labels = brain_like_shape(shape)
    write_zarr(labels, folder / "big.zarr")
    counts = np.bincount(labels.ravel(), minlength=6)
    del labels
    cmd = [sys.executable, "-m", "napari_swa_imesh.cli", "mesh", str(folder / "big.zarr"),
           "-o", str(folder / "big.pvtu"), "--exclude", "0", "--workers", "2", "--memory",
           "4GB", "--json"]
    row = run_tree(cmd)
    print(f"big case {shape} ({np.prod(shape) / 1e6:.1f} M voxels), 2 workers at --memory "
          "4GB:")
    if row["rc"]:
        print(f"  failed: {row.get('error')}")
        return
    r = row["report"]
    exact = all(abs(r["volumes"][str(m)] - counts[m]) == 0 for m in range(1, 6))
    print(f"  {row['seconds']:.0f} s, peak of the process tree {row['peak'] / 2**30:.2f} GB "
          f"(goal <= 10 GB: {'met' if row['peak'] <= 10 * 2**30 else 'NOT met'}), "
          f"{r['pieces']} pieces of {r['block']}^3, {r['n_elements']} elements, worst ratio "
          f"{r['worst_ratio']:.4f} (bound {r['quality_bound']:.4f}), seams conforming, "
          f"per-material volumes equal to the voxel counts: {exact}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=256, help="side of the throughput volume")
    ap.add_argument("--big", action="store_true", help="only the 400x470x380 case (heavy)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=".") as tmp:
        if args.big:
            big(Path(tmp))
        else:
            throughput(args.n, Path(tmp))


if __name__ == "__main__":
    main()
