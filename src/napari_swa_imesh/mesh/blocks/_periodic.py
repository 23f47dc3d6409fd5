"""Periodic faces block by block: the box split to one lattice cell, then matched.

In memory (``_lattice.split_box_faces``) every leaf touching the image box is split down
to one lattice cell, so opposite box faces carry the same vertices and facets,
translated. Block-wise the same split is one more reason to split a coarse cell, known
from its position alone: :func:`box_cells` marks, per level, the cells inside the image
that touch its box, and the global balance of the coarse grids goes on from there (the
same recurrence, so the same balanced tree). The face diagonals follow the rule the
in-memory mesher picks (:func:`diagonal_rule`).

The check: the block on a box face and the block on the opposite face must put the same
facets there. :func:`box_facets` gives a piece's box-side facets as rows of global ids,
those of a low side translated across the box; :func:`periodic_mismatches` compares the
two sides of each axis on every face cell both sides mesh (a cell whose voxel is
excluded on one side has facets on the other side only, as in memory).
"""

from __future__ import annotations

import numpy as np

__all__ = ["box_cells", "box_facets", "diagonal_rule", "periodic_mismatches"]


def diagonal_rule(shape, periodic: bool) -> str:
    """The 3-D face-diagonal rule the in-memory mesher uses for a lattice of `shape`
    (``_imesh._mesh_tree``): ``"lowest"`` for a periodic mesh with an odd extent (the
    parity rule would not survive the translation by the box), else ``"parity"``."""
    return "lowest" if periodic and any(int(n) % 2 for n in shape) else "parity"


def box_cells(shape, grid_shape, k: int) -> np.ndarray:
    """(grid_shape) bool: the level-`k` cells inside the image of `shape` (lattice
    cells) that touch its box (origin 0 or far side at or past the extent on some axis)."""
    d = len(shape)
    inside = np.ones(grid_shape, bool)
    touch = np.zeros(grid_shape, bool)
    for a in range(d):
        c = np.arange(grid_shape[a], dtype=np.int64)
        view = [1] * d
        view[a] = grid_shape[a]
        inside &= ((c << k) < shape[a]).reshape(view)
        touch |= ((c == 0) | (((c + 1) << k) >= shape[a])).reshape(view)
    return inside & touch


def box_facets(piece, shape) -> dict:
    """``(axis, side) -> (F, d)`` sorted rows of global ids of the piece's box-side facets
    (groups ``xmin`` .. ``zmax``), a low side's translated by the extent along its axis."""
    d = len(shape)
    strides = np.array([int(np.prod([n + 1 for n in shape[a + 1:]])) for a in range(d)],
                       np.int64)
    out = {}
    for a in range(d):
        name = "xyz"[d - 1 - a]
        for end, sign in (("min", -1), ("max", 1)):
            if f"{name}{end}" not in piece.groups:
                continue
            ids = np.sort(piece.gid[piece.groups[f"{name}{end}"][0]], axis=1)
            if sign < 0:
                ids = ids + int(shape[a]) * strides[a]
            out[(a, sign)] = ids
    return out


def _cell_keys(ids: np.ndarray, shape) -> np.ndarray:
    """The face cell of each facet (rows of global ids): the global id of its
    componentwise lowest corner (every box facet lies in one lattice cell's face)."""
    d = len(shape)
    strides = [int(np.prod([int(n) + 1 for n in shape[a + 1:]])) for a in range(d)]
    key = np.zeros(len(ids), np.int64)
    for a in range(d):
        coord = (ids // strides[a]) % (int(shape[a]) + 1)              # (F, d)
        key += coord.min(axis=1) * strides[a]
    return key


def periodic_mismatches(plan, boxes: dict) -> list[str]:
    """Compare opposite box faces.

    Parameters
    ----------
    plan : BlockPlan
    boxes : dict
        Block index -> its :func:`box_facets` (missing: an empty piece).

    Returns
    -------
    list of str
        One sentence per axis whose two faces differ on a cell both mesh.
    """
    d = len(plan.shape)
    out = []
    empty = np.zeros((0, d), np.int64)
    for a in range(d):
        sides = []
        for sign, at in ((-1, 0), (1, plan.grid[a] - 1)):
            rows = [b.get((a, sign), empty) for i, b in boxes.items() if i[a] == at]
            ids = np.concatenate([empty] + rows)
            sides.append((ids, _cell_keys(ids, plan.shape)))
        common = np.intersect1d(sides[0][1], sides[1][1])
        kept = []
        for ids, keys in sides:
            ids = ids[np.isin(keys, common)]
            kept.append(ids[np.lexsort(ids.T[::-1])] if len(ids) else ids)
        if kept[0].shape != kept[1].shape or not np.array_equal(kept[0], kept[1]):
            out.append(f"the two box faces across axis {a} differ ({len(kept[0])} vs "
                       f"{len(kept[1])} facets on the cells both mesh)")
    return out
