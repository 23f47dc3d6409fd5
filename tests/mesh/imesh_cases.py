"""Seeded label images shared by the IMESH tests (not a test module)."""

from __future__ import annotations

import numpy as np

from napari_swa_imesh.data import blob_labels


def blobs(shape, n_materials: int, seed: int, sigma: float = 2.0) -> np.ndarray:
    """Smooth random regions: big homogeneous leaves with boundaries of every slope
    (:func:`napari_swa_imesh.data.blob_labels`, which the benchmarks use too)."""
    return blob_labels(shape, n_materials, seed=seed, sigma=sigma)


def noise(shape, n_materials: int, seed: int, p: float = 0.05) -> np.ndarray:
    """Mostly one material with isolated random pixels of the others (fine next to coarse)."""
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.int64)
    spots = rng.random(shape) < p
    lab[spots] = rng.integers(1, max(2, n_materials), spots.sum())
    return lab


def thin(shape, seed: int) -> np.ndarray:
    """One-pixel lines (2-D) or sheets and lines (3-D) of two materials in a background."""
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.int64)
    for axis in range(len(shape)):
        idx = [slice(None)] * len(shape)
        idx[axis] = int(rng.integers(0, shape[axis]))
        lab[tuple(idx)] = 1 + axis % 2
    line = tuple(int(rng.integers(0, n)) for n in shape[:-1]) + (slice(None),)
    lab[line] = 3
    return lab


def cases(dim: int):
    """(name, labels) pairs: several materials, thin structures, one material, non-dyadic."""
    shapes = {2: [(16, 16), (23, 37), (5, 64), (33, 17)],
              3: [(8, 8, 8), (11, 14, 9), (16, 5, 12)]}[dim]
    out = []
    for k, shape in enumerate(shapes):
        out.append((f"blobs3-{shape}", blobs(shape, 3, seed=k)))
        out.append((f"blobs2-{shape}", blobs(shape, 2, seed=10 + k, sigma=3.0)))
        out.append((f"noise-{shape}", noise(shape, 4, seed=20 + k)))
        out.append((f"thin-{shape}", thin(shape, seed=30 + k)))
    out.append(("one-material", np.full(shapes[1], 7, np.int64)))
    out.append(("uniform-random", np.random.default_rng(99).integers(0, 3, shapes[1])))
    return out
