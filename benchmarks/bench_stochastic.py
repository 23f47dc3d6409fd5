"""The stochastic step's verification errors and run times, at sizes beyond the tests.

* Matheron (2-D): an isotropic log-normal field (log k std 1) has k_eff = k_G; the
  ensemble mean's relative error and its distance in Monte-Carlo standard errors.
* 3-D small variance: k_eff / k_G = 1 + sigma^2 / 6; the fitted coefficient against 1/6
  (per sample against its own geometric mean and variance, which removes most noise); P1,
  as P2 on these tetrahedra takes minutes.
* The brain-like 3-D phantom (CSF, grey, white matter): segmented, its signatures drawn
  into fields, k_eff along x; seconds with 1 and 2 workers (the samples agree exactly).

Run: ``python -m benchmarks.bench_stochastic [--quick]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from napari_swa_imesh.data import TISSUE_NAMES, tissue_phantom
from napari_swa_imesh.segmentation import samples_from_truth, segment
from napari_swa_imesh.simulate import signature_tile_size, stochastic_k_eff


def _rows(std: float) -> list[dict]:
    return [{"label": 1, "name": "one", "tiles": 99, "mean_mean": 0.0, "mean_std": std}]


def matheron(size: int, samples: int, order: int = 2) -> None:
    t = time.perf_counter()
    r = stochastic_k_eff(np.ones((size, size), np.uint8), _rows(1.0), samples=samples,
                         correlation=4.0, property_map="log-linear:0,1", seed=1, order=order)
    for axis in ("x", "y"):
        s = r.statistics(axis)
        print(f"Matheron 2-D {size}^2 P{order}, {samples} samples, {axis}: k_eff {s['mean']:.4f} "
              f"+- {s['sem']:.4f}, k_G 1: error {100 * (s['mean'] - 1):+.2f} % "
              f"({(s['mean'] - 1) / s['sem']:+.2f} s.e.)")
    print(f"  {time.perf_counter() - t:.1f} s, {r.n_cells} elements")


def small_variance_3d(size: int, samples: int, sigma: float, order: int = 1) -> None:
    t = time.perf_counter()
    r = stochastic_k_eff(np.ones((size,) * 3, np.uint8), _rows(sigma), samples=samples,
                         correlation=4.0, seed=2, axes="x", order=order)
    ratio = r.samples["x"] / np.exp(r.log_k_moments[:, 0])
    c = (ratio.mean() - 1) / r.log_k_moments[:, 1].mean()
    print(f"3-D {size}^3 P{order}, sigma {sigma}, {samples} samples: coefficient {c:.4f} vs 1/6 "
          f"(error {100 * (6 * c - 1):+.1f} %); {time.perf_counter() - t:.1f} s, "
          f"{r.n_cells} elements")


def phantom(samples: int) -> None:
    image, truth = tissue_phantom((32, 48, 48), noise=0.09, seed=0)
    run = segment(image, samples_from_truth(truth, names=dict(TISSUE_NAMES)),
                  spacing=(2.0, 1.0, 1.0))
    tile = signature_tile_size(run.signatures)
    out = {}
    for workers in (1, 2):
        t = time.perf_counter()
        out[workers] = stochastic_k_eff(run.labels, run.signatures, samples=samples,
                                        correlation=tile * np.array([2.0, 1.0, 1.0]),
                                        spacing=(2.0, 1.0, 1.0), axes="x",
                                        property_map="log-linear:-4,5", seed=0,
                                        workers=workers)
        print(f"phantom 3-D 32x48x48, {samples} samples, {workers} worker(s): "
              f"{time.perf_counter() - t:.1f} s")
    print(out[1].describe())
    print("  samples identical for 1 and 2 workers:",
          bool(np.array_equal(out[1].samples["x"], out[2].samples["x"])))


def main() -> None:
    parser = argparse.ArgumentParser(description="stochastic k_eff verification")
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args().quick
    for order in (2, 1):       # P1 is biased high by the element-wise field
        matheron(48 if quick else 96, 16 if quick else 100, order)
    small_variance_3d(24 if quick else 32, 6 if quick else 16, 0.3)
    phantom(8 if quick else 32)


if __name__ == "__main__":
    main()
