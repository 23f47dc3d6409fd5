"""Second-order pieces: mid-edge nodes whose global ids need no communication.

A piece of order 2 is its linear piece plus one node at the midpoint of each of its
edges, numbered after its corners as ``formats._order2.MidEdges`` numbers them (so a
piece is written exactly as ``write_mesh(..., order=2)`` writes a mesh). The midpoint of
the edge ``(p, q)`` of integer lattice points is the point ``p + q`` of the *doubled*
lattice (``2 n + 1`` points per axis); its global id is ``C + key(p + q)``, where ``C``
is the number of corner ids (``prod(n + 1)``: corner ids are kept as at order 1) and
``key`` the C-order key in the doubled lattice. Every piece holding an edge on a block
face computes the same id from the edge's two corners alone, so joining the pieces by
``global_id`` joins their mid-edge nodes too.
"""

from __future__ import annotations

import math

import numpy as np

from ..formats._order2 import MidEdges, with_mid_nodes

__all__ = ["mid_nodes", "n_global_ids", "quadratic_arrays"]


def n_global_ids(shape, order: int) -> int:
    """How many global ids a lattice of `shape` cells uses at `order` (1 or 2).

    Examples
    --------
    >>> n_global_ids((2, 3), 1), n_global_ids((2, 3), 2)
    (12, 47)
    """
    corners = math.prod(int(n) + 1 for n in shape)
    return corners if order == 1 else corners + math.prod(2 * int(n) + 1 for n in shape)


def mid_nodes(points: np.ndarray, cells: np.ndarray, shape
              ) -> tuple[MidEdges, np.ndarray, np.ndarray]:
    """The mid-edge nodes of a piece.

    Parameters
    ----------
    points : (N, d) ndarray of int64
        The piece's lattice points.
    cells : (M, d+1) ndarray of int
        Its elements.
    shape : tuple of int
        The lattice's shape (cells per axis) of the whole volume.

    Returns
    -------
    edges : MidEdges
        The piece's unique edges; mid-edge node ``N + e`` is the midpoint of edge ``e``.
    twice : (E, d) ndarray of int64
        Twice each midpoint's coordinates (a point of the doubled lattice).
    gid : (E,) ndarray of int64
        Their global ids.
    """
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    edges = MidEdges(cells, len(points))
    a, b = np.divmod(edges.keys, edges.n_points)
    twice = points[a] + points[b]                                     # (E, d)
    strides = np.array([math.prod(2 * n + 1 for n in shape[k + 1:]) for k in range(d)],
                       np.int64)
    return edges, twice, n_global_ids(shape, 1) + twice @ strides


def quadratic_arrays(points: np.ndarray, gid: np.ndarray, cells: np.ndarray,
                     facets: list[np.ndarray], shape):
    """Points (lattice units, float), global ids, cells and facets of a piece at order 2.

    `cells` and `facets` are as they are to be written (corners in the files' order); the
    mid-edge nodes follow the corners in VTK's order (``_order2.EDGE_ORDER["vtk"]``).
    """
    edges, twice, mid_gid = mid_nodes(points, cells, shape)
    pts = np.concatenate([points.astype(np.float64), twice / 2.0])
    return (pts, np.concatenate([gid, mid_gid]), with_mid_nodes(cells, edges, "vtk"),
            [with_mid_nodes(f, edges, "vtk") for f in facets])
