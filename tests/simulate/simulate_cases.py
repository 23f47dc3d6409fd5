"""Seeded label images shared by the adaptive-simulation tests (not a test module)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def blobs(shape, sigma=1.5, seed=0, materials=3):
    """Smoothed noise cut at its quantiles: `materials` regions of about equal volume."""
    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), sigma)
    return (np.digitize(f, np.quantile(f, np.linspace(0, 1, materials + 1)[1:-1])) + 1
            ).astype(np.uint8)
