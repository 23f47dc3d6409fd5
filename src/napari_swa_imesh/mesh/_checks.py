"""Checks a user (and the test suite) can run on any mesh of a label image.

Every check works in index space (points divided by the mesh's spacing), where pixel ``i``
spans ``[i, i+1)`` along each axis and its centre is ``i + 0.5``. Tolerances are 1e-9 of a
pixel: template meshes have integer vertices, so their predicates are exact in floating
point; the tolerance only matters for meshes made elsewhere.
"""

from __future__ import annotations

import math

import numpy as np

from .._tree import build_tree
from .._validation import as_labels
from ._quality import _det, signed_volumes
from ._types import Mesh

__all__ = ["check_mesh", "rasterize_materials"]

_TOL = 1e-9
_CANDIDATES_PER_CHUNK = 1 << 22


def _index_points(mesh: Mesh) -> np.ndarray:
    spacing = np.asarray(mesh.spacing if mesh.spacing else (1.0,) * mesh.ndim, dtype=float)
    return np.asarray(mesh.points, dtype=float) / spacing


def _rasterize(points: np.ndarray, cells: np.ndarray, material: np.ndarray, shape):
    """Which elements cover each pixel centre.

    Returns flat arrays over the pixels: number of covering elements, and the smallest and
    largest covering material (so a pixel covered by two materials is visible).
    """
    d = len(shape)
    n_pix = math.prod(shape)
    hits = np.zeros(n_pix, np.int64)
    mat_lo = np.full(n_pix, np.iinfo(np.int64).max)
    mat_hi = np.full(n_pix, np.iinfo(np.int64).min)
    if len(cells) == 0:
        return hits, mat_lo, mat_hi
    p = points[cells]  # (M, d+1, d)
    lo = np.ceil(p.min(axis=1) - 0.5 - _TOL).astype(np.int64)
    hi = np.floor(p.max(axis=1) - 0.5 + _TOL).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, np.array(shape) - 1)
    extent = hi - lo + 1  # (M, d) pixel centres per axis in the bounding box
    edges = p[:, 1:] - p[:, :1]  # (M, d, d), rows are edge vectors
    det = _det(edges)
    ok = (extent > 0).all(axis=1) & (np.abs(det) > _TOL)
    inv = np.zeros_like(edges)
    inv[ok] = _inv(edges[ok])
    # bucket by the bounding box side rounded up to a power of two
    side = np.left_shift(1, np.ceil(np.log2(np.maximum(extent.max(axis=1), 1))).astype(np.int64))
    for b in np.unique(side[ok]):
        offsets = np.stack(np.unravel_index(np.arange(int(b) ** d), (int(b),) * d), axis=1)
        members = np.flatnonzero(ok & (side == b))
        step = max(1, _CANDIDATES_PER_CHUNK // len(offsets))
        for start in range(0, len(members), step):
            e = members[start:start + step]
            pix = lo[e, None, :] + offsets[None]  # (n, b^d, d)
            inbox = (pix <= hi[e, None, :]).all(axis=-1)
            lam = np.einsum("nkd,nde->nke", pix + 0.5 - p[e, None, 0, :], inv[e])  # barycentric 1..d
            inside = inbox & (lam >= -_TOL).all(axis=-1) & (lam.sum(axis=-1) <= 1 + _TOL)
            which, k = np.nonzero(inside)
            flat = np.ravel_multi_index(tuple(pix[which, k].T), shape)
            mats = material[e[which]].astype(np.int64)
            hits += np.bincount(flat, minlength=n_pix)
            np.minimum.at(mat_lo, flat, mats)
            np.maximum.at(mat_hi, flat, mats)
    return hits, mat_lo, mat_hi


def rasterize_materials(mesh: Mesh, *, fill: int = -1) -> np.ndarray:
    """Paint each element's material at the pixel centres it covers.

    Parameters
    ----------
    mesh : Mesh
        A 2-D or 3-D mesh with ``shape`` and ``spacing`` set (as :func:`mesh_labels` does).
    fill : int
        Value of pixels no element covers.

    Returns
    -------
    ndarray of int64, shape ``mesh.shape``
        Where elements of different materials cover one pixel centre, the largest wins.

    Examples
    --------
    >>> from napari_swa_imesh.mesh._imesh import mesh_labels
    >>> lab = np.array([[1, 0], [2, 2]])
    >>> rasterize_materials(mesh_labels(lab, exclude=[0])).tolist()
    [[1, -1], [2, 2]]
    """
    hits, _, mat_hi = _rasterize(_index_points(mesh), np.asarray(mesh.cells),
                                 np.asarray(mesh.material), tuple(mesh.shape))
    out = np.where(hits > 0, mat_hi, fill)
    return out.reshape(mesh.shape)


def _inv(m: np.ndarray) -> np.ndarray:
    """(n, d, d) inverses by the adjugate (d = 2, 3); callers skip singular matrices."""
    det = _det(m)[:, None, None]
    if m.shape[-1] == 2:
        adj = np.stack([np.stack([m[:, 1, 1], -m[:, 0, 1]], -1),
                        np.stack([-m[:, 1, 0], m[:, 0, 0]], -1)], 1)
        return adj / det
    # rows of the inverse's transpose are cross products of the columns... of m's rows
    a, b, c = m[:, 0], m[:, 1], m[:, 2]
    return np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=2) / det


def _group_rows(rows: np.ndarray):
    """Group equal rows of an (F, k) int array: (inverse (F,), counts (U,)).

    Packs each row into one int64 when the ids fit, else sorts lexicographically; both
    are far faster than ``np.unique(axis=0)``.
    """
    n = int(rows.max()) + 1 if rows.size else 1
    k = rows.shape[1]
    if n ** k < 2**63:
        key = np.zeros(len(rows), np.int64)
        for j in range(k):
            key = key * n + rows[:, j]
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        new = np.r_[True, sorted_key[1:] != sorted_key[:-1]]
    else:
        order = np.lexsort(rows.T[::-1])
        sorted_rows = rows[order]
        new = np.r_[True, (sorted_rows[1:] != sorted_rows[:-1]).any(axis=1)]
    group_sorted = np.cumsum(new) - 1
    inverse = np.empty(len(rows), np.int64)
    inverse[order] = group_sorted
    counts = np.bincount(group_sorted)
    return inverse, counts


def _facets(cells: np.ndarray):
    """All facets of all cells: sorted vertex ids (F, d) and the opposite vertex (F,)."""
    n_vert = cells.shape[1]
    facets = np.concatenate([np.delete(cells, i, axis=1) for i in range(n_vert)])
    opposite = np.concatenate([cells[:, i] for i in range(n_vert)])
    return np.sort(facets, axis=1), opposite


def _side(points, facets, opposite) -> np.ndarray:
    """Sign of the opposite vertex relative to the facet with its vertices in sorted order."""
    base = points[facets[:, 0]]
    a = points[facets[:, 1]] - base
    c = points[opposite] - base
    if points.shape[1] == 2:
        return np.sign(a[:, 0] * c[:, 1] - a[:, 1] * c[:, 0])
    b = points[facets[:, 2]] - base
    return np.sign(np.einsum("fi,fi->f", a, np.cross(b, c)))


def _outward_normal(points, facets, opposite) -> np.ndarray:
    """Unit normal of each facet pointing away from its opposite vertex."""
    fp = points[facets]  # (F, d, d)
    if fp.shape[-1] == 2:
        t = fp[:, 1] - fp[:, 0]
        n = np.stack([-t[:, 1], t[:, 0]], axis=1)
    else:
        n = np.cross(fp[:, 1] - fp[:, 0], fp[:, 2] - fp[:, 0])
    flip = np.einsum("fi,fi->f", n, points[opposite] - fp[:, 0]) > 0
    n[flip] *= -1
    with np.errstate(divide="ignore", invalid="ignore"):
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def check_mesh(mesh: Mesh, labels, *, exclude=()) -> dict:
    """Check that a mesh represents a label image faithfully.

    Parameters
    ----------
    mesh : Mesh
        Triangles (2-D) or tetrahedra (3-D), ``points`` in physical units with
        ``mesh.spacing`` (index space if spacing is empty).
    labels : (M, N[, P]) array_like of int
        The label image that was meshed.
    exclude : iterable of int
        Materials that were not meshed.

    Returns
    -------
    dict
        Booleans ``conforming`` (every facet shared by at most two elements, from opposite
        sides; facets seen once lie on the image box or next to an excluded material),
        ``positive_volume`` (no element of zero or negative volume), ``volume_sum``
        (element volumes add up to the included pixels times the voxel volume),
        ``inside_one_leaf`` (every element inside one maximal homogeneous block of the
        labels), ``labels_recovered`` (rasterising element materials at pixel centres gives
        the labels back, excluded pixels uncovered) and ``all_passed``; and the numbers
        behind them (``n_facets_shared_3plus``, ``n_misoriented_facets``,
        ``n_boundary_facets_off_box``, ``n_unmatched_facets``, ``min_volume``,
        ``volume_error``, ``n_outside_leaf``, ``n_pixels_wrong``, ``n_unused_points``).

    Examples
    --------
    >>> from napari_swa_imesh.mesh._imesh import mesh_labels
    >>> lab = np.array([[1, 1], [1, 2]])
    >>> check_mesh(mesh_labels(lab), lab)["all_passed"]
    True
    """
    lab = as_labels(labels, min_ndim=2, max_ndim=3)
    d = lab.ndim
    if mesh.ndim != d or mesh.cells.ndim != 2 or mesh.cells.shape[1] != d + 1:
        raise ValueError(f"a {d}-D label image needs a {d}-D mesh of {d + 1}-vertex cells; got points "
                         f"{mesh.points.shape} and cells {mesh.cells.shape}.")
    exclude_arr = np.asarray(list(exclude) if not np.isscalar(exclude) else [exclude], dtype=np.int64)
    included = ~np.isin(lab, exclude_arr)
    points = _index_points(mesh)
    cells = np.asarray(mesh.cells, dtype=np.int64)
    material = np.asarray(mesh.material, dtype=np.int64)
    voxel = float(np.prod(mesh.spacing)) if mesh.spacing else 1.0
    out: dict = {}

    used = np.zeros(len(points), dtype=bool)
    used[cells.ravel()] = True
    out["n_unused_points"] = int((~used).sum())

    # volumes, in voxels
    vol = signed_volumes(points, cells)
    out["min_volume"] = float(vol.min() * voxel) if vol.size else 0.0
    out["positive_volume"] = bool((vol > _TOL).all())
    n_inc = int(included.sum())
    out["volume_error"] = float((vol.sum() - n_inc) * voxel)
    out["volume_sum"] = bool(abs(vol.sum() - n_inc) <= 1e-9 * max(1, n_inc))

    # facets: shared by at most two cells, from opposite sides; the rest on the boundary
    facets, opposite = _facets(cells)
    inverse, counts = _group_rows(facets)
    per_occurrence = counts[inverse]
    out["n_facets_shared_3plus"] = int((counts >= 3).sum())
    twice = per_occurrence == 2
    side_sum = np.bincount(inverse[twice], weights=_side(points, facets[twice], opposite[twice]),
                           minlength=len(counts))
    out["n_misoriented_facets"] = int(((counts == 2) & (side_sum != 0)).sum())
    once = per_occurrence == 1
    fpts = points[facets[once]]  # (B, d, d)
    box = np.array(lab.shape, dtype=float)
    on_box = ((np.abs(fpts).max(axis=1) <= _TOL) |
              (np.abs(fpts - box).max(axis=1) <= _TOL)).any(axis=1)
    off = ~on_box
    out["n_boundary_facets_off_box"] = int(off.sum())
    normal = _outward_normal(points, facets[once][off], opposite[once][off])
    probe = fpts[off].mean(axis=1) + 0.25 * normal
    pix = np.floor(probe).astype(np.int64)
    in_image = ((pix >= 0) & (pix < np.array(lab.shape))).all(axis=1)
    probe_included = np.zeros(len(pix), dtype=bool)
    probe_included[in_image] = included[tuple(pix[in_image].T)]
    out["n_unmatched_facets"] = int((probe_included | ~np.isfinite(normal).all(axis=1)).sum())
    out["conforming"] = (out["n_facets_shared_3plus"] == 0 and out["n_misoriented_facets"] == 0
                         and out["n_unmatched_facets"] == 0)

    # every element inside one maximal homogeneous block of the labels
    tree = build_tree(lab)
    leaf_map = tree.to_image(values=np.arange(len(tree)))
    corner_pts = points[cells]  # (M, d+1, d)
    centroid = np.floor(corner_pts.mean(axis=1)).astype(np.int64)
    in_image = ((centroid >= 0) & (centroid < np.array(lab.shape))).all(axis=1)
    leaf = np.zeros(len(cells), dtype=np.int64)
    leaf[in_image] = leaf_map[tuple(centroid[in_image].T)]
    lo = tree.origin[leaf][:, None, :]
    hi = lo + tree.size[leaf][:, None, None]
    inside = ((corner_pts >= lo - _TOL) & (corner_pts <= hi + _TOL)).all(axis=(1, 2)) & in_image
    out["n_outside_leaf"] = int((~inside).sum())
    out["inside_one_leaf"] = out["n_outside_leaf"] == 0

    # the label image recovered at pixel centres
    hits, mat_lo, mat_hi = _rasterize(points, cells, material, lab.shape)
    flat_lab = lab.ravel()
    flat_inc = included.ravel()
    wrong = np.where(flat_inc, (hits == 0) | (mat_lo != flat_lab) | (mat_hi != flat_lab), hits > 0)
    out["n_pixels_wrong"] = int(wrong.sum())
    out["labels_recovered"] = out["n_pixels_wrong"] == 0

    out["all_passed"] = all(out[k] for k in ("conforming", "positive_volume", "volume_sum",
                                             "inside_one_leaf", "labels_recovered"))
    return out
