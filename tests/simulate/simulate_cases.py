"""Label images shared by the simulation tests (not a test module)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def blobs(shape, sigma=1.5, seed=0, materials=3):
    """Smoothed noise cut at its quantiles: `materials` regions of about equal volume."""
    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), sigma)
    return (np.digitize(f, np.quantile(f, np.linspace(0, 1, materials + 1)[1:-1])) + 1
            ).astype(np.uint8)


def checkerboard(n: int, side: int) -> np.ndarray:
    """An n x n board of `side` x `side` squares of materials 1 and 2 (1 in the corner):
    the two-phase medium whose k_eff is sqrt(k1 k2) exactly (Dykhne)."""
    squares = np.arange(n * side) // side
    return (np.add.outer(squares, squares) % 2 + 1).astype(np.uint8)
