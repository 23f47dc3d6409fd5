"""Speed and memory of the SWA tile-feature engine, with naive peers in the same run.

Usage::

    python benchmarks/bench_features.py            # 2-D 1024^2 and 3-D 256^3, float32
    python benchmarks/bench_features.py --quick    # 2-D 256^2 and 3-D 64^3 (smoke test)

Every measurement runs in a fresh subprocess so that its peak resident memory
(``ru_maxrss``) is its own. "extra MB" is the peak minus the high-water mark
just before the call (interpreter, imports and the float32 input already
counted). "wall s" is elapsed time and "cpu s" the process's CPU time (the
steadier figure when other jobs share the cores); both are the best of
``--repeat`` calls after a warm-up call on a 16^d image. Absolute seconds
drift on a shared machine, so each row also gives its CPU-time ratio to a
naive peer timed in the same run:

- ``naive pyramid``: for every scale, reshape into blocks and call
  ``scipy.stats.describe`` (two passes over all pixels per scale, O(N log N)),
  the peer of ``moment_pyramid``;
- ``describe@3``: the same at scale 3 only, the peer of the scale-3 features.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np

TARGET_SECONDS = 3.0  # moments, all scales, 256^3 (lead's budget: 5 s with classification)


def _blocks(image: np.ndarray, scale: int) -> np.ndarray:
    """(tiles, 2**(scale*d)) copy of the dyadic tiles of `image`."""
    block = 2**scale
    shape: list[int] = []
    for side in image.shape:
        shape += [side // block, block]
    view = image.reshape(shape)
    order = tuple(range(0, 2 * image.ndim, 2)) + tuple(range(1, 2 * image.ndim, 2))
    return view.transpose(order).reshape(-1, block**image.ndim)


def _naive_describe(image: np.ndarray, scale: int):
    from scipy import stats

    return stats.describe(_blocks(image.astype(np.float64), scale), axis=1, ddof=0)


def _job(name: str, image: np.ndarray):
    from napari_swa_imesh.segmentation._correlation import tile_correlation_lengths
    from napari_swa_imesh.segmentation._entropy import tile_entropy
    from napari_swa_imesh.segmentation._moments import moment_pyramid

    top = int(max(image.shape)).bit_length() - 1
    if name == "moment_pyramid":
        return lambda: moment_pyramid(image, max_scale=top)
    if name == "tile_entropy@3":
        return lambda: tile_entropy(image, 3)
    if name == "tile_correlation_lengths@3":
        return lambda: tile_correlation_lengths(image, 3)
    if name == "naive pyramid":
        return lambda: [_naive_describe(image, j) for j in range(1, top + 1)]
    if name == "describe@3":
        return lambda: _naive_describe(image, 3)
    raise ValueError(f"unknown job {name!r}")


def _run_child(name: str, shape: tuple[int, ...], repeat: int) -> dict:
    # warm-up on a small image: lazy imports and first-call costs stay out of the timing
    _job(name, np.random.default_rng(1).random((16,) * len(shape), dtype=np.float32))()
    image = np.random.default_rng(0).random(shape, dtype=np.float32)
    work = _job(name, image)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    best, best_cpu = np.inf, np.inf
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = work()
        best = min(best, time.perf_counter() - start)
        best_cpu = min(best_cpu, time.process_time() - start_cpu)
        del result
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"seconds": best, "cpu": best_cpu, "peak_mb": peak / 1024,
            "extra_mb": (peak - before) / 1024}


def _measure(name: str, shape: tuple[int, ...], repeat: int) -> dict:
    command = [sys.executable, __file__, "--child", name, "--shape", *map(str, shape),
               "--repeat", str(repeat)]
    done = subprocess.run(command, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    parser.add_argument("--repeat", type=int, default=1, help="calls per job; the best is kept")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--shape", type=int, nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_run_child(args.child, tuple(args.shape), args.repeat)))
        return

    cases = [(256, 256), (64, 64, 64)] if args.quick else [(1024, 1024), (256, 256, 256)]
    jobs = ["moment_pyramid", "naive pyramid", "tile_entropy@3",
            "tile_correlation_lengths@3", "describe@3"]
    peers = {"moment_pyramid": "naive pyramid", "tile_entropy@3": "describe@3",
             "tile_correlation_lengths@3": "describe@3"}
    header = (f"{'image (float32)':<16} {'job':<28} {'wall s':>7} {'cpu s':>7} {'peak MB':>8} "
              f"{'extra MB':>9}  cpu ratio to peer")
    print(header)
    print("-" * len(header))
    for shape in cases:
        results = {job: _measure(job, shape, args.repeat) for job in jobs}
        label = "x".join(map(str, shape))
        for job in jobs:
            row = results[job]
            ratio = ""
            if job in peers:
                peer = peers[job]
                ratio = f"{row['cpu'] / results[peer]['cpu']:.2f} x {peer}"
            print(f"{label:<16} {job:<28} {row['seconds']:7.3f} {row['cpu']:7.3f} "
                  f"{row['peak_mb']:8.0f} {row['extra_mb']:9.0f}  {ratio}")
        if len(shape) == 3 and not args.quick:
            seconds = results["moment_pyramid"]["seconds"]
            verdict = "within" if seconds < TARGET_SECONDS else "OVER"
            print(f"{'':<16} moment_pyramid {verdict} the {TARGET_SECONDS:.0f} s target for 256^3 "
                  f"(wall {seconds:.2f} s; on a loaded machine compare the cpu column)")
    print("peers: 'naive pyramid' = scipy.stats.describe on reshaped blocks at every scale; "
          "'describe@3' = the same at scale 3 only.")


if __name__ == "__main__":
    main()
