"""Mesh writers: wall time and peak memory of writing a 128^3-class mesh per format.

Run:  python benchmarks/bench_write.py [--n 128] [--formats .msh .inp .vtu]

The brain-like label volume of ``bench_mesh.py`` is meshed once (cached as ``.npz`` in the
temporary folder); each format is then written in a process of its own, so that the peak
resident memory (``ru_maxrss``) above the loaded mesh is the writer's own. Extra keyword
arguments of ``write_mesh`` can be given as JSON (``--kwargs '{"binary": false}'``).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _cache(n: int) -> Path:
    path = Path(tempfile.gettempdir()) / f"swa-imesh-bench-write-{n}.npz"
    if not path.exists():
        sys.path.insert(0, str(Path(__file__).parent))
        from bench_mesh import brain_like

        from napari_swa_imesh.mesh import mesh_labels

        mesh = mesh_labels(brain_like(n, 3), exclude=(0,))
        np.savez(path, points=mesh.points, cells=mesh.cells, material=mesh.material,
                 quality=mesh.quality, spacing=mesh.spacing, shape=mesh.shape)
    return path


def run_one(cache: str, suffix: str, kwargs: dict) -> dict:
    from napari_swa_imesh.mesh import Mesh, write_mesh

    data = np.load(cache)
    mesh = Mesh(data["points"], data["cells"], data["material"], {"quality": data["quality"]},
                spacing=tuple(data["spacing"]), shape=tuple(data["shape"]))
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with tempfile.TemporaryDirectory() as folder:
        t = time.perf_counter()
        written = write_mesh(mesh, Path(folder) / f"m{suffix}", **kwargs)
        seconds = time.perf_counter() - t
        size = sum(p.stat().st_size for p in written)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"format": suffix, "kwargs": kwargs, "elements": mesh.n_cells,
            "points": len(mesh.points), "seconds": seconds,
            "peak_above_mesh_mb": (peak - base) / 1024, "mesh_mb": base / 1024,
            "file_mb": size / 2**20}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=128)
    parser.add_argument("--formats", nargs="+", default=[".msh", ".inp", ".vtu"])
    parser.add_argument("--kwargs", default="{}")
    parser.add_argument("--one", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(args.one[0], args.one[1], json.loads(args.one[2]))))
        return 0
    cache = _cache(args.n)
    print("| format | options | elements | seconds | peak above mesh (MB) | file (MB) |")
    print("|---|---|---|---|---|---|")
    for suffix in args.formats:
        res = subprocess.run([sys.executable, __file__, "--one", str(cache), suffix,
                              args.kwargs], capture_output=True, text=True, check=True)
        r = json.loads(res.stdout.strip().splitlines()[-1])
        print(f"| {r['format']} | {r['kwargs'] or ''} | {r['elements']} | {r['seconds']:.2f} | "
              f"{r['peak_above_mesh_mb']:.0f} | {r['file_mb']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
