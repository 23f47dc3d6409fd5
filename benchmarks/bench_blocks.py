"""Block-wise meshing benchmark (issue 27): throughput against the in-memory mesher, 1 vs
2 workers, and a big volume under a memory cap.

Run:  python benchmarks/bench_blocks.py [--n 256] [--no-weak] [--weak] [--big [--compare]]

Every run is a ``swa-imesh mesh`` subprocess, so both paths pay the same: reading the
labels, meshing, checks, facet groups and writing (``.vtu`` in memory, ``.pvtu`` pieces
block-wise). Peak memory is that of the whole process tree (the command, the Dask
scheduler, nanny and worker processes), sampled every 0.2 s with psutil.

1. A brain-like ``n^3`` volume (``bench_mesh.brain_like``; background excluded) stored as
   Zarr in 128^3 chunks: the in-memory mesh, then block-wise with 1 and 2 workers at
   ``--memory 4GB``; seconds per million voxels (wall and CPU of the process tree: the
   machine is shared, so the CPU ratio is the steadier one), and the element counts
   (equal when the block is the in-memory root, else the difference of cutting leaves
   at block faces).
2. Weak scaling: 1 worker on ``n^3`` against 2 workers on ``2n x n x n`` (twice the work);
   efficiency ``t1 / t2`` (1 is perfect), with the load average around each run.
   ``--weak`` runs only this pair and adds what each task measured inside itself
   (``mesh.blocks._timing``): CPU and busy seconds per worker, the busy fraction of each
   round (1: no worker waited), worker CPU per voxel against the 1-worker run and the
   critical path from those CPU times, which do not depend on the machine's load.
3. ``--big``: a brain-like 400 x 470 x 380 volume in 128^3 chunks, 2 workers at
   ``--memory 4GB``; its peak must stay under 10 GB. Heavy: run it alone, as
   ``flock /work/wt/heavy.lock python benchmarks/bench_blocks.py --big``; ``--compare``
   also runs the in-memory mesh of the same labels (about 5 GB measured; skipped when
   fewer than 18 GB are free) and compares the element counts.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
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

    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = [0]
    cpu: dict[int, float] = {}          # last CPU seconds seen per process of the tree
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
                        t = p.cpu_times()
                        cpu[p.pid] = max(cpu.get(p.pid, 0.0), t.user + t.system)
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
    # the command and the children it waited for, exactly; the sampled tree catches
    # processes it did not wait for (and misses their last 0.2 s)
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    own = usage.ru_utime + usage.ru_stime - _reaped[0]
    _reaped[0] += own
    root = cpu.get(proc.pid, 0.0)
    others = [v for k, v in cpu.items() if k != proc.pid]
    row = {"seconds": time.perf_counter() - t0, "rc": proc.returncode, "peak": peak[0],
           "cpu": max(own, sum(cpu.values())), "load": (load, os.getloadavg()[0]),
           # the command's own CPU plus its busiest child's: the wall time the run would
           # take with a core per process (workers run side by side)
           "critical": root + max(others, default=0.0)}
    if proc.returncode:
        row["error"] = err.strip().splitlines()[-1] if err.strip() else ""
    else:
        try:
            row["report"] = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            row["report"] = {}
    return row


_reaped = [0.0]                 # CPU seconds of the children reaped so far


def _elements(row: dict) -> int | None:
    r = row.get("report", {})
    return r.get("n_elements") or r.get("elements") or (r.get("mesh") or {}).get("n_elements")


def _blocks_cmd(zarr: Path, out: Path, workers: int) -> list[str]:
    return [sys.executable, "-m", "napari_swa_imesh.cli", "mesh", str(zarr), "-o", str(out),
            "--exclude", "0", "--workers", str(workers), "--memory", "4GB", "--json"]


def _table(rows: dict, n_vox: dict, base: str) -> None:
    print(f"{'run':26s} {'wall s':>7s} {'cpu s':>7s} {'s/Mvox':>7s} {'x wall':>7s} "
          f"{'x cpu':>6s} {'peak GB':>7s} {'elements':>10s} {'block':>5s} {'load':>10s}")
    for name, row in rows.items():
        if row["rc"]:
            print(f"{name:26s} failed: {row.get('error')}")
            continue
        ref = rows[base]
        print(f"{name:26s} {row['seconds']:7.1f} {row['cpu']:7.1f} "
              f"{row['seconds'] / n_vox[name] * 1e6:7.2f} "
              f"{row['seconds'] / n_vox[name] / (ref['seconds'] / n_vox[base]):7.2f} "
              f"{row['cpu'] / n_vox[name] / (ref['cpu'] / n_vox[base]):6.2f} "
              f"{row['peak'] / 2**30:7.2f} {_elements(row) or 0:10d} "
              f"{row['report'].get('block', '-')!s:>5s} "
              f"{row['load'][0]:4.1f}->{row['load'][1]:4.1f}")


def throughput(n: int, folder: Path, weak: bool = True) -> None:
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
            _blocks_cmd(folder / "lab.zarr", folder / f"b{w}.pvtu", w))
    voxels = dict.fromkeys(rows, n_vox)
    if weak:
        doubled = brain_like_shape((2 * n, n, n), seed=1)
        write_zarr(doubled, folder / "lab2.zarr")
        del doubled
        name = f"blocks, 2 workers, {2 * n}x{n}x{n}"
        rows[name] = run_tree(_blocks_cmd(folder / "lab2.zarr", folder / "w2.pvtu", 2))
        voxels[name] = 2 * n_vox
    print(f"brain-like {n}^3 ({n_vox / 1e6:.1f} M voxels), Zarr chunks 128^3, background "
          "excluded; a shared 2-core machine: 'x wall'/'x cpu' per voxel against the "
          "in-memory run, 'load' the 1-minute load average before -> after")
    _table(rows, voxels, "in-memory (.vtu)")
    one, two = rows["blocks, 1 worker(s)"], rows["blocks, 2 worker(s)"]
    if not (one["rc"] or two["rc"]):
        print(f"strong scaling, same {n}^3 volume: 1 -> 2 workers "
              f"{one['seconds'] / two['seconds']:.2f}x faster")
    if weak and not (one["rc"] or rows[name]["rc"]):
        two = rows[name]
        print(f"weak scaling, 1 worker on {n}^3 -> 2 workers on {2 * n}x{n}x{n}: efficiency "
              f"t1/t2 = {one['seconds'] / two['seconds']:.2f} in wall time (1 is perfect); "
              f"CPU per voxel {two['cpu'] / 2 / one['cpu']:.2f}x the 1-worker run's; on the "
              f"critical path (the command's CPU plus its busiest worker's) "
              f"{one['critical']:.1f} s -> {two['critical']:.1f} s, efficiency "
              f"{one['critical'] / two['critical']:.2f}")
        print("note: with sched_autogroup (Linux's default) every process of one command "
              "shares one CPU share while other sessions keep the cores busy, so a second "
              "worker adds no CPU to a run on a loaded machine: the wall-time ratio then "
              "measures the machine, the critical-path ratio the code")


def _task_line(name: str, row: dict) -> str:
    """Per-worker CPU and busy seconds and the rounds' busy fractions, from the tasks'
    own timings (``report["tasks"]``, measured inside each task)."""
    t = row["report"]["tasks"]
    workers = ", ".join(f"{w['cpu_s']:.1f}/{w['busy_s']:.1f}" for w in t["workers"])
    rounds = ", ".join(f"{k} {v['busy_fraction']:.2f}" for k, v in t["rounds"].items())
    return (f"  {name}: {t['n_workers']} worker(s), CPU/busy s per worker [{workers}], "
            f"busy fraction per round [{rounds}], command's CPU {t['client_cpu_s']:.1f} s")


def weak(n: int, folder: Path) -> None:
    """Weak scaling only: 1 worker on ``n^3`` against 2 workers on ``2n x n x n``, with
    figures that do not depend on the machine's load (in-task CPU per worker, busy
    fractions) beside the wall times."""
    runs = {}
    for w, shape, seed in ((1, (n, n, n), 0), (2, (2 * n, n, n), 1)):
        write_zarr(brain_like_shape(shape, seed=seed), folder / f"w{w}.zarr")
        runs[w] = run_tree(_blocks_cmd(folder / f"w{w}.zarr", folder / f"w{w}.pvtu", w))
        if runs[w]["rc"]:
            print(f"{w} worker(s) failed: {runs[w].get('error')}")
            return
    one, two = runs[1], runs[2]
    t1, t2 = one["report"]["tasks"], two["report"]["tasks"]
    cpu1 = sum(w["cpu_s"] for w in t1["workers"])
    cpu2 = sum(w["cpu_s"] for w in t2["workers"])
    busiest = max(w["cpu_s"] for w in t2["workers"])
    path1 = t1["client_cpu_s"] + cpu1
    path2 = t2["client_cpu_s"] + busiest
    print(f"weak scaling, brain-like, Zarr chunks 128^3, --memory 4GB, background excluded:"
          f" 1 worker on {n}^3, 2 workers on {2 * n}x{n}x{n}")
    for name, row in (("1 worker", one), ("2 workers", two)):
        print(f"  {name}: {row['seconds']:.1f} s wall, {row['cpu']:.1f} s CPU of the tree, "
              f"peak {row['peak'] / 2**30:.2f} GB, {_elements(row)} elements, load "
              f"{row['load'][0]:.1f}->{row['load'][1]:.1f}")
        print(_task_line(name, row))
    print(f"  wall-time efficiency t1/t2 = {one['seconds'] / two['seconds']:.2f} (1 is "
          "perfect; meaningful on an idle machine)")
    print(f"  load-independent: worker CPU per voxel {cpu2 / 2 / cpu1:.2f}x the 1-worker "
          f"run's (1: no extra work), busiest worker {busiest / (cpu2 / 2):.2f}x the mean "
          f"(1: balanced), mesh-round busy fraction {t2['rounds']['mesh']['busy_fraction']:.2f}"
          f" (1: workers never wait), critical path (command CPU + busiest worker's CPU) "
          f"{path1:.1f} s -> {path2:.1f} s: efficiency {path1 / path2:.2f}")


def big(folder: Path, compare: bool = False) -> None:
    """The 400 x 470 x 380 case; with `compare`, also the in-memory mesh of the same
    labels (``--memory-limit off``; about 7-16 GB: only when the machine has them free)."""
    import psutil

    shape = (400, 470, 380)
    labels = brain_like_shape(shape)
    write_zarr(labels, folder / "big.zarr")
    counts = np.bincount(labels.ravel(), minlength=6)
    if compare:
        np.save(folder / "big.npy", labels)
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
    print(f"  {row['seconds']:.0f} s wall, {row['cpu']:.0f} s CPU (critical path "
          f"{row['critical']:.0f} s), peak of the process tree {row['peak'] / 2**30:.2f} GB "
          f"(goal <= 10 GB: {'met' if row['peak'] <= 10 * 2**30 else 'NOT met'}), "
          f"{r['pieces']} pieces of {r['block']}^3, {r['n_elements']} elements, worst ratio "
          f"{r['worst_ratio']:.4f} (bound {r['quality_bound']:.4f}), seams conforming, "
          f"per-material volumes equal to the voxel counts: {exact}")
    if not compare:
        return
    free = psutil.virtual_memory().available
    if free < 18 * 2**30:
        print(f"  in-memory comparison skipped: {free / 2**30:.1f} GB available, 18 needed")
        return
    mem = run_tree([sys.executable, "-m", "napari_swa_imesh.cli", "mesh",
                    str(folder / "big.npy"), "-o", str(folder / "mem.vtu"), "--exclude", "0",
                    "--memory-limit", "off", "--json"])
    if mem["rc"]:
        print(f"  in-memory run failed: {mem.get('error')}")
        return
    n_mem = _elements(mem) or 0
    diff = (r["n_elements"] - n_mem) / max(1, n_mem)
    print(f"  in memory (.vtu): {mem['seconds']:.0f} s wall, {mem['cpu']:.0f} s CPU, peak "
          f"{mem['peak'] / 2**30:.2f} GB, {n_mem} elements; block-wise count "
          f"{100 * diff:+.3f} % of it (goal within 1 %: "
          f"{'met' if abs(diff) <= 0.01 else 'NOT met'})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=256, help="side of the throughput volume")
    ap.add_argument("--big", action="store_true", help="only the 400x470x380 case (heavy)")
    ap.add_argument("--no-weak", action="store_true", help="skip the weak-scaling run")
    ap.add_argument("--weak", action="store_true",
                    help="only weak scaling (1 worker n^3, 2 workers 2n x n x n), with "
                         "per-worker CPU and busy fractions")
    ap.add_argument("--compare", action="store_true",
                    help="with --big: also the in-memory mesh (needs ~18 GB free)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=".") as tmp:
        if args.big:
            big(Path(tmp), compare=args.compare)
        elif args.weak:
            weak(args.n, Path(tmp))
        else:
            throughput(args.n, Path(tmp), weak=not args.no_weak)


if __name__ == "__main__":
    main()
