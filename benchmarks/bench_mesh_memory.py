"""Peak memory of ``swa-imesh mesh`` against :func:`estimate_mesh_memory`.

Run:  python benchmarks/bench_mesh_memory.py [--sizes 64 128 256] [--kind brain blob]

Each case runs ``swa-imesh mesh LABELS.npy -o MESH.vtu --json`` in a fresh process that
reports its own peak RSS (``ru_maxrss``); the estimate comes from the same run's
``memory_estimate_bytes``. The estimate should lie above every measured peak.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from _peak import PEAK_SOURCE
from bench_mesh import brain_like

CHILD = PEAK_SOURCE + (
    "import json, sys\n"
    "from napari_swa_imesh.cli import main\n"
    "rc = main(sys.argv[1:])\n"
    "print(json.dumps({'rc': rc, 'peak': peak_bytes()}), file=sys.stderr)\n"
)


def random_blobs(n: int, seed: int = 1) -> np.ndarray:
    """Four materials from smoothed noise (sigma 3 voxels): dense boundaries."""
    from scipy import ndimage

    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal((n,) * 3)
                                .astype(np.float32), 3)
    return np.digitize(f, np.quantile(f, [0.25, 0.5, 0.75])).astype(np.uint8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--kind", nargs="+", default=["brain", "blob"])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kind:
            for n in args.sizes:
                labels = brain_like(n, 3) if kind == "brain" else random_blobs(n)
                path = Path(tmp) / f"{kind}{n}.npy"
                np.save(path, labels)
                proc = subprocess.run(
                    [sys.executable, "-c", CHILD, "mesh", str(path), "-o",
                     str(Path(tmp) / "m.vtu"), "--force", "--json", "--memory-limit", "off"],
                    capture_output=True, text=True)
                peak = json.loads(proc.stderr.strip().splitlines()[-1])["peak"]
                report = json.loads(proc.stdout)
                est = report["memory_estimate_bytes"]
                print(f"{kind} {n}^3: {report['elements']} elements, peak {peak / 2**30:.2f} "
                      f"GB, estimate {est / 2**30:.2f} GB (peak/estimate {peak / est:.2f})",
                      flush=True)


if __name__ == "__main__":
    main()
