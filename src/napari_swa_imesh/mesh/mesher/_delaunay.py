"""The reference's last step, kept for comparison: Qhull Delaunay of the leaf corners.

On a face-balanced tree's corners Qhull returns flat simplices (whole cubes of
co-spherical points in 3-D); they are dropped and counted, and the mesh is reported as it
is (``mesh_labels`` runs the checks on it).
"""

from __future__ import annotations

import time

import numpy as np

from ..._region_tree import RegionTree
from ..model._quality import quality_data, signed_volumes
from ._templates import lattice, mark_corners

__all__ = ["delaunay_mesh"]


def delaunay_mesh(bal: RegionTree, meshed: np.ndarray):
    """The reference's step: Qhull Delaunay of the unique corners of the meshed leaves."""
    from scipy.spatial import Delaunay

    seconds = {}
    t = time.perf_counter()
    shape, strides = lattice(bal)
    is_vertex = mark_corners(bal, meshed, shape, strides)
    points = np.stack(np.unravel_index(np.flatnonzero(is_vertex), shape), axis=1).astype(np.float64)
    del is_vertex
    seconds["vertices"] = time.perf_counter() - t

    t = time.perf_counter()
    simplices = Delaunay(points).simplices.astype(np.intp)
    seconds["simplices"] = time.perf_counter() - t

    t = time.perf_counter()
    vol = signed_volumes(points, simplices)
    flip = vol < 0
    simplices[flip, 0], simplices[flip, 1] = simplices[flip, 1], simplices[flip, 0].copy()
    scale = float(np.abs(vol).max()) if vol.size else 1.0
    zero = np.abs(vol) <= 1e-12 * scale
    # material of the leaf under each centroid; a centroid in padding or an excluded
    # material means the simplex lies outside the meshed region (hull of a concave set)
    centroid = points[simplices].mean(axis=1)
    pix = np.minimum(np.floor(centroid).astype(np.int64), np.array(bal.padded_shape) - 1)
    leaf_map = bal.to_image(values=np.arange(len(bal)), crop=False)
    leaf = leaf_map[tuple(pix.T)]
    keep = ~zero & meshed[leaf]
    info = {"n_delaunay_simplices": int(len(simplices)), "n_zero_volume": int(zero.sum()),
            "n_outside_dropped": int((~zero & ~meshed[leaf]).sum())}
    simplices, leaf = simplices[keep], leaf[keep]
    cell_data = quality_data(points, simplices)
    # drop vertices no kept simplex uses
    used = np.zeros(len(points), bool)
    used[simplices.ravel()] = True
    new_id = np.cumsum(used) - 1
    seconds["quality"] = time.perf_counter() - t
    return points[used], new_id[simplices].astype(np.intp), leaf, cell_data, info, seconds
