"""Second-order elements: one mid-edge node per unique edge, and each format's node order.

A 6-node triangle or 10-node tetrahedron is the linear element plus the midpoints of its
edges. The mid-edge nodes are numbered after the N corner nodes: node ``N + e`` is the
midpoint of edge ``e`` of the sorted list of unique edges, so elements that share an edge
share its node. The order in which an element lists its mid-edge nodes differs between
formats (corners 0-based, in the element's own corner order):

=============================  =============================  ==========================
family (formats)               triangle (6 nodes)             tetrahedron (10 nodes)
=============================  =============================  ==========================
``vtk`` (VTK, meshio, XDMF,    01 12 20                       01 12 20 03 13 23
Abaqus CPS6/C3D10)
``gmsh`` (types 9 and 11)      01 12 20                       01 12 20 03 23 13
``triangle`` (``-o2``)         12 20 01 (opposite corner k)   --
``tetgen`` (``-o2``)           --                             23 03 01 12 13 02
=============================  =============================  ==========================

Facets of second order (3-node lines: ``0 1 01``; 6-node triangles: ``01 12 20``) follow
the same rule in every format, TetGen's ``.face`` included. Sources: VTK's
``vtkQuadraticTetra``, Gmsh's "Node ordering" section (tet10 nodes 8 and 9 on edges 2-3
and 1-3), Triangle's ``.ele`` page (the k-th extra node opposite corner k), TetGen 1.6's
``highorder()`` (``edge2ver``), checked against the programs' own ``-o2`` output.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MidEdges", "EDGE_ORDER", "with_mid_nodes"]

#: (corners per element) -> corner pairs whose midpoints follow the corners, per family.
EDGE_ORDER = {
    "vtk": {2: [(0, 1)], 3: [(0, 1), (1, 2), (2, 0)],
            4: [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]},
    "gmsh": {2: [(0, 1)], 3: [(0, 1), (1, 2), (2, 0)],
             4: [(0, 1), (1, 2), (2, 0), (0, 3), (2, 3), (1, 3)]},
    "triangle": {2: [(0, 1)], 3: [(1, 2), (2, 0), (0, 1)]},
    "tetgen": {3: [(0, 1), (1, 2), (2, 0)],
               4: [(2, 3), (0, 3), (0, 1), (1, 2), (1, 3), (0, 2)]},
}
_CHUNK = 1 << 20          # elements per pass when collecting edges


def _unique(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct `keys`: a sort and a comparison (numpy 2's hashing ``np.unique``
    takes 40 times longer on these keys, multiples of N plus a small number)."""
    keys = np.sort(keys, axis=None)
    return keys[np.concatenate([[True], keys[1:] != keys[:-1]])] if len(keys) else keys


class MidEdges:
    """The unique edges of a simplex mesh, each with the id of its mid-edge node.

    Parameters
    ----------
    cells : (M, d+1) ndarray of int
        Triangles or tetrahedra.
    n_points : int
        Number of corner nodes N; mid-edge nodes get ids N .. N+E-1.

    Examples
    --------
    >>> edges = MidEdges(np.array([[0, 1, 2], [1, 3, 2]]), 4)
    >>> len(edges), edges.ids(np.array([2]), np.array([1])).tolist()
    (5, [6])
    """

    def __init__(self, cells: np.ndarray, n_points: int):
        cells = np.asarray(cells)
        pairs = np.array(EDGE_ORDER["vtk"][cells.shape[1]])           # (k, 2)
        self.n_points = int(n_points)
        found = [np.zeros(0, np.int64)]
        for start in range(0, len(cells), _CHUNK):                    # unique per chunk,
            block = cells[start:start + _CHUNK]                        # then once more
            found.append(_unique(self._keys(block[:, pairs[:, 0]], block[:, pairs[:, 1]])))
        self.keys = _unique(np.concatenate(found))

    def __len__(self) -> int:
        return len(self.keys)

    def _keys(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
        return np.minimum(a, b) * self.n_points + np.maximum(a, b)

    def ids(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Node ids of the midpoints of edges ``(a, b)`` (any shape, either direction)."""
        return self.n_points + np.searchsorted(self.keys, self._keys(a, b))

    def midpoints(self, points: np.ndarray) -> np.ndarray:
        """(E, d) coordinates of the mid-edge nodes: ``(p_a + p_b) / 2`` in `points`' frame."""
        a, b = np.divmod(self.keys, self.n_points)
        return (points[a] + points[b]) / 2


def with_mid_nodes(corners: np.ndarray, edges: MidEdges | None, family: str = "vtk"
                   ) -> np.ndarray:
    """`corners` (k, c) followed by their mid-edge nodes in `family`'s order.

    Returns `corners` itself when `edges` is None (first order).
    """
    if edges is None:
        return corners
    pairs = np.array(EDGE_ORDER[family][corners.shape[1]])
    return np.hstack([corners, edges.ids(corners[:, pairs[:, 0]], corners[:, pairs[:, 1]])])
