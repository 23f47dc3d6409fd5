"""Interface refinement block by block: which coarse cells touch a material interface.

In memory (``_lattice.lattice_tree`` with ``refine=K``) the tree is built on a lattice
``2**K`` times finer than the (subdivided) voxels, then every leaf that shares a facet
with an interface (a voxel face between two labels, one of them meshed; the box sides
are none) is split, recursively, down to one lattice cell. A cell's split depends only
on the voxel faces on its own boundary, so a block decides it from its window (its
lattice cells and a one-cell halo): :func:`interface_cells` marks, per level, the cells
of the block with an interface face on their boundary. Or'ed into the block's mixed
grids, the global balance of the coarse grids then gives the in-memory tree (a cell
with an interface face inside it is mixed anyway, so the split stays a tree).
"""

from __future__ import annotations

import numpy as np

from ..._region_tree import PAD_LABEL

__all__ = ["interface_cells"]


def interface_cells(window: np.ndarray, top: int, exclude) -> list[np.ndarray]:
    """Per level k = 1..top, ``(block >> k,)*d`` bool: the level-k cell of the block has
    an interface face on its boundary.

    Parameters
    ----------
    window : ndarray of int64
        The block's lattice cells and a one-cell halo (``PAD_LABEL`` outside the image),
        ``(block + 2,)*d``.
    top : int
        The block's level (``block = 2**top``).
    exclude : sequence of int
        Materials not meshed: a face between two of them is no interface.

    Returns
    -------
    list of ndarray
    """
    d = window.ndim
    b = window.shape[0] - 2
    excl = np.asarray(list(exclude), np.int64)
    meshed = (window != PAD_LABEL) & ~np.isin(window, excl)
    out = [np.zeros((b >> k,) * d, bool) for k in range(1, top + 1)]
    core = slice(1, b + 1)
    for a in range(d):
        lo = tuple(slice(0, b + 1) if c == a else core for c in range(d))
        hi = tuple(slice(1, b + 2) if c == a else core for c in range(d))
        # (b+1 planes along a, b cells along the others): the face there is an interface
        faces = ((window[lo] != window[hi]) & (window[lo] != PAD_LABEL)
                 & (window[hi] != PAD_LABEL) & (meshed[lo] | meshed[hi]))
        for k in range(1, top + 1):
            # planes at multiples of 2**k, any face within a level-k cell's extent
            faces = faces[tuple(slice(None, None, 2) if c == a else slice(None)
                                for c in range(d))]
            shape = []
            for c, n in enumerate(faces.shape):
                shape += [n] if c == a else [n // 2, 2]
            faces = faces.reshape(shape).any(axis=tuple(
                i for i in range(len(shape)) if i not in _kept(a, d)))
            low = tuple(slice(None, -1) if c == a else slice(None) for c in range(d))
            high = tuple(slice(1, None) if c == a else slice(None) for c in range(d))
            out[k - 1] |= faces[low] | faces[high]
    return out


def _kept(a: int, d: int) -> list[int]:
    """Axes of the reshaped face array that stay (the plane axis and each cell axis)."""
    kept, i = [], 0
    for c in range(d):
        kept.append(i)
        i += 1 if c == a else 2
    return kept
