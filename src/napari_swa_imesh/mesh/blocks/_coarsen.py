"""Coarsening block by block: each block votes its own ``2**c`` cubes of voxels.

In memory (``mesher._coarsen.coarsen_labels``) every cube of ``2**c`` voxels per axis,
on a grid from index 0, takes its majority label (ties to the lowest; a cube cut by
the image's far end votes with the voxels it holds) before the mesher sees the labels.
A cube's vote depends on its own voxels only, so a block reads its voxel window widened
to whole cubes (:func:`read_slices`), votes them with the same function and keeps its
window (:func:`coarsened`): the labels every block meshes are the in-memory coarsened
labels, and the rest (balance, pieces, checks) is unchanged.
"""

from __future__ import annotations

import numpy as np

from ..mesher._coarsen import coarsen_labels

__all__ = ["coarsened", "read_slices"]


def read_slices(plan, index) -> tuple[tuple[slice, ...], tuple[slice, ...] | None]:
    """The voxels to read for block `index` and the part of them that is its voxel
    window (None: no coarsening, read the window itself)."""
    vox = plan.voxel_window(index)[0]
    if not plan.coarsen:
        return vox, None
    side = 1 << plan.coarsen
    factors = plan.factors or (1,) * len(plan.shape)
    wide, crop = [], []
    for s, n, f in zip(vox, plan.shape, factors):
        start = s.start - s.start % side
        stop = min(n // f, -(-s.stop // side) * side)
        wide.append(slice(start, stop))
        crop.append(slice(s.start - start, s.stop - start))
    return tuple(wide), tuple(crop)


def coarsened(voxels: np.ndarray, plan, crop) -> np.ndarray:
    """The block's voxel window of the coarsened labels, from the whole cubes read."""
    if crop is None:
        return voxels
    return coarsen_labels(voxels, plan.coarsen)[0][crop]
