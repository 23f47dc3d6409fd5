"""Second-order pieces: mid-edge nodes whose global ids need no communication.

A piece of order 2 is its linear piece plus one node at the midpoint of each of its
edges, listed in every element (and facet) after its corners in VTK's order
(``formats._order2.EDGE_ORDER["vtk"]``, as ``write_mesh(..., order=2)`` writes a mesh).
The midpoint of the edge ``(p, q)`` of integer lattice points is the point ``p + q`` of
the *doubled* lattice (``2 n + 1`` points per axis); its global id is ``C + key(p + q)``,
where ``C`` is the number of corner ids (``prod(n + 1)``: corner ids are kept as at
order 1) and ``key`` the C-order key in the doubled lattice. Every piece holding an edge
on a block face computes the same id from the edge's two corners alone, so joining the
pieces by ``global_id`` joins their mid-edge nodes too. The key is also what a piece
numbers its mid-edge nodes by (one sort of the elements' edge keys; no edge table).
"""

from __future__ import annotations

import math

import numpy as np

from ..formats._order2 import EDGE_ORDER

__all__ = ["n_global_ids", "quadratic_arrays"]


def n_global_ids(shape, order: int) -> int:
    """How many global ids a lattice of `shape` cells uses at `order` (1 or 2).

    Examples
    --------
    >>> n_global_ids((2, 3), 1), n_global_ids((2, 3), 2)
    (12, 47)
    """
    corners = math.prod(int(n) + 1 for n in shape)
    return corners if order == 1 else corners + math.prod(2 * int(n) + 1 for n in shape)


def _doubled_strides(shape) -> np.ndarray:
    d = len(shape)
    return np.array([math.prod(2 * int(n) + 1 for n in shape[k + 1:]) for k in range(d)],
                    np.int64)


def _edge_keys(points: np.ndarray, rows: np.ndarray, strides: np.ndarray) -> np.ndarray:
    """(R, E) doubled-lattice keys of the midpoints of each row's edges in VTK's order."""
    pairs = EDGE_ORDER["vtk"][rows.shape[1]]
    keys = np.zeros((len(rows), len(pairs)), np.int64)
    for a in range(points.shape[1]):
        x = np.ascontiguousarray(points[:, a])
        for j, (u, v) in enumerate(pairs):
            keys[:, j] += (x[rows[:, u]] + x[rows[:, v]]) * strides[a]
    return keys


def quadratic_arrays(points: np.ndarray, gid: np.ndarray, cells: np.ndarray,
                     facets: list[np.ndarray], shape):
    """Points (lattice units, float), global ids, cells and facets of a piece at order 2.

    Parameters
    ----------
    points : (N, d) ndarray of int64
        The piece's lattice points.
    gid : (N,) ndarray of int64
        Their global ids.
    cells : (M, d+1) ndarray of int
        Its elements, corners as they are to be written.
    facets : list of (F, d) ndarray of int
        Its facet groups' facets, corners as they are to be written.
    shape : tuple of int
        The lattice's shape (cells per axis) of the whole volume.

    Returns
    -------
    points : (N + E, d) ndarray of float64
        The corners, then the E mid-edge nodes (half-integer lattice coordinates).
    gid : (N + E,) ndarray of int64
    cells : (M, (d+1)(d+2)/2) ndarray of intp
    facets : list of (F, d(d+1)/2) ndarray of intp
    """
    shape = tuple(int(n) for n in shape)
    strides = _doubled_strides(shape)
    keys = _edge_keys(points, cells, strides)                         # (M, E per cell)
    uniq, inverse = np.unique(keys, return_inverse=True)
    n = len(points)
    twice = np.stack([(uniq // strides[a]) % (2 * shape[a] + 1) for a in range(len(shape))],
                     axis=1)                                          # (E, d) doubled
    out_cells = np.hstack([cells, n + inverse.reshape(keys.shape)]).astype(np.intp)
    del keys, inverse
    out_facets = [np.hstack([f, n + np.searchsorted(uniq, _edge_keys(points, f, strides))]
                            ).astype(np.intp) for f in facets]
    return (np.concatenate([points.astype(np.float64), twice / 2.0]),
            np.concatenate([gid, n_global_ids(shape, 1) + uniq]), out_cells, out_facets)
