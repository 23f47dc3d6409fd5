"""Mesh writers: wall time and peak memory of writing a 128^3-class mesh per format.

Run:  python benchmarks/bench_write.py [--n 128] [--formats .msh .inp .vtu facet_groups]

The brain-like label volume of ``bench_mesh.py`` is meshed once (cached as ``.npz`` in the
temporary folder); each format is then written in a process of its own, so that the peak
resident memory (``ru_maxrss``) above the loaded mesh is the writer's own; a second process
measures the peak of the memory numpy and Python allocate while writing (``tracemalloc``,
steadier than the resident peak). ``facet_groups`` as a format times
``mesh.facet_groups(mesh)`` alone (the writers' shared first step). The peers:
``meshio.<suffix>`` hands the whole mesh, converted, to meshio's own writer of that format
(its defaults; no facet groups), so ``meshio.xdmf`` is the XDMF writer before issue 13:
``--formats .inp meshio.inp .vtu meshio.vtu .xdmf meshio.xdmf --kwargs
'{"facet_groups": "none"}'`` compares like with like. Extra keyword
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


def run_one(cache: str, suffix: str, kwargs: dict, trace: bool) -> dict:
    import tracemalloc

    from napari_swa_imesh.mesh import Mesh, facet_groups, write_mesh

    data = np.load(cache)
    mesh = Mesh(data["points"], data["cells"], data["material"], {"quality": data["quality"]},
                spacing=tuple(data["spacing"]), shape=tuple(data["shape"]))
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if trace:                      # numpy reports its buffers to tracemalloc
        tracemalloc.start()
    with tempfile.TemporaryDirectory() as folder:
        t, c = time.perf_counter(), time.process_time()
        if suffix == "facet_groups":
            facet_groups(mesh)
            written = []
        elif suffix.startswith("meshio."):
            written = _meshio_peer(mesh, Path(folder), suffix[len("meshio"):], kwargs)
        else:
            written = write_mesh(mesh, Path(folder) / f"m{suffix}", **kwargs)
        seconds, cpu = time.perf_counter() - t, time.process_time() - c
        size = sum(p.stat().st_size for p in written)
    traced = tracemalloc.get_traced_memory()[1] if trace else 0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"format": suffix, "kwargs": kwargs, "elements": mesh.n_cells,
            "points": len(mesh.points), "seconds": seconds, "cpu": cpu,
            "peak_above_mesh_mb": (peak - base) / 1024, "traced_peak_mb": traced / 2**20,
            "file_mb": size / 2**20}


_MESHIO_FORMAT = {".xdmf": "xdmf", ".inp": "abaqus", ".vtu": "vtu", ".msh": "gmsh"}


def _meshio_peer(mesh, folder: Path, suffix: str, kwargs: dict) -> list[Path]:
    """meshio's own writer of `suffix`, given the whole mesh converted (before issues 10
    and 13 the package wrote .vtu and .xdmf this way)."""
    import meshio

    from napari_swa_imesh.mesh.formats._export import _meshio_of
    from napari_swa_imesh.mesh.formats._prepare import ExportMesh

    ex = ExportMesh(mesh, order=kwargs.get("order", 1), groups="none")
    meshio.write(folder / f"m{suffix}", _meshio_of(ex), file_format=_MESHIO_FORMAT[suffix])
    return [p for p in (folder / f"m{suffix}", folder / "m.h5") if p.exists()]


def _spawn(cache, suffix, kwargs: str, trace: bool) -> dict:
    res = subprocess.run([sys.executable, __file__, "--one", str(cache), suffix, kwargs,
                          str(int(trace))], capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=128)
    parser.add_argument("--formats", nargs="+", default=[".msh", ".inp", ".vtu"])
    parser.add_argument("--kwargs", default="{}")
    parser.add_argument("--one", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        cache, suffix, kwargs, trace = args.one
        print(json.dumps(run_one(cache, suffix, json.loads(kwargs), bool(int(trace)))))
        return 0
    cache = _cache(args.n)
    print("| format | options | elements | wall s | CPU s | peak RSS above mesh (MB) | "
          "traced peak (MB) | files (MB) |")
    print("|---|---|---|---|---|---|---|---|")
    for suffix in args.formats:
        timed = _spawn(cache, suffix, args.kwargs, trace=False)
        traced = _spawn(cache, suffix, args.kwargs, trace=True)
        print(f"| {suffix} | {timed['kwargs'] or ''} | {timed['elements']} | "
              f"{timed['seconds']:.2f} | {timed['cpu']:.2f} | {timed['peak_above_mesh_mb']:.0f} | "
              f"{traced['traced_peak_mb']:.0f} | {timed['file_mb']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
