"""Checks a user (and the test suite) can run on any mesh of a label image.

Every check works in index space (points divided by the mesh's spacing), where pixel ``i``
spans ``[i, i+1)`` along each axis and its centre is ``i + 0.5``. Tolerances are 1e-9 of a
pixel: template meshes have integer vertices, so their predicates are exact in floating
point; the tolerance only matters for meshes made elsewhere.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from .._tree import RegionTree, _build_tree, leaf_finder
from ._lattice import labels_on_lattice
from .._validation import as_labels
from ._quality import _det, signed_volumes
from ._types import Mesh

__all__ = ["MeshChecks", "check_mesh", "rasterize_materials"]

_TOL = 1e-9
_CANDIDATES_PER_CHUNK = 1 << 22
_CELLS_PER_CHUNK = 1 << 20
_FACETS_PER_PASS = 1 << 23
_SLAB_VOXELS = 1 << 22


@dataclass(frozen=True)
class MeshChecks(Mapping):
    """What :func:`check_mesh` found: one flag per check and the counts behind it.

    Also reads as a read-only mapping with the same keys (``checks["all_passed"]``,
    ``dict(checks)``), the form the command line prints with ``--json``.

    Attributes
    ----------
    conforming : bool
        Every facet shared by at most two elements, from opposite sides; facets seen once
        lie on the image box or next to an excluded material.
    positive_volume : bool
        No element of zero or negative volume.
    volume_sum : bool
        Element volumes add up to the included pixels times the voxel volume.
    inside_one_leaf : bool
        Every element inside one maximal homogeneous block of the labels.
    labels_recovered : bool
        Element materials rasterised at pixel centres give the labels back, excluded
        pixels uncovered.
    finite : bool
        Every point coordinate and float value in ``cell_data`` is a number (NaN or inf
        means the spacing over- or underflowed).
    n_unused_points, n_facets_shared_3plus, n_misoriented_facets, n_boundary_facets_off_box,
    n_unmatched_facets, n_outside_leaf, n_nonfinite_values : int
        The counts behind the flags.
    n_pixels_wrong : int
        Missed or wrongly covered pixels plus covering elements of a wrong material.
    min_volume, volume_error : float
        Smallest element volume and (sum of volumes - included volume), physical units.
    """

    # in the order the command line has always printed them
    n_unused_points: int
    min_volume: float
    positive_volume: bool
    volume_error: float
    volume_sum: bool
    n_facets_shared_3plus: int
    n_misoriented_facets: int
    n_boundary_facets_off_box: int
    n_unmatched_facets: int
    conforming: bool
    n_outside_leaf: int
    inside_one_leaf: bool
    n_pixels_wrong: int
    labels_recovered: bool
    n_nonfinite_values: int
    finite: bool

    @property
    def all_passed(self) -> bool:
        return all((self.conforming, self.positive_volume, self.volume_sum,
                    self.inside_one_leaf, self.labels_recovered, self.finite))

    def to_dict(self) -> dict:
        """Plain JSON-ready dict: every field, then ``all_passed``."""
        return {**asdict(self), "all_passed": self.all_passed}

    def __getitem__(self, key):
        if key == "all_passed" or key in self.__dataclass_fields__:
            return getattr(self, key)
        raise KeyError(key)

    def __iter__(self):
        return iter((*self.__dataclass_fields__, "all_passed"))

    def __len__(self) -> int:
        return len(self.__dataclass_fields__) + 1


def _index_points(mesh: Mesh) -> np.ndarray:
    """Points in pixel units: the mesh's own array when the spacing is 1 (no copy)."""
    spacing = np.asarray(mesh.spacing if mesh.spacing else (1.0,) * mesh.ndim, dtype=float)
    if (spacing == 1).all():
        return mesh.points
    return mesh.points / spacing


def _at(lab: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Labels at flat pixel indices, without a flat copy of a non-contiguous array."""
    if lab.flags.c_contiguous:
        return lab.reshape(-1)[flat]
    return lab[np.unravel_index(flat, lab.shape)]


def _excluded(values: np.ndarray, exclude: np.ndarray) -> np.ndarray:
    return np.isin(values, exclude) if exclude.size else np.zeros(values.shape, bool)


def count_excluded(lab: np.ndarray, exclude: np.ndarray) -> int:
    """Pixels of `lab` holding a label of `exclude`, counted in slabs (no image-size mask).

    Examples
    --------
    >>> count_excluded(np.array([[0, 1], [0, 2]]), np.array([0, 2]))
    3
    """
    if not exclude.size:
        return 0
    step = max(1, _SLAB_VOXELS // max(1, math.prod(lab.shape[1:])))
    return sum(int(np.count_nonzero(np.isin(lab[i:i + step], exclude)))
               for i in range(0, lab.shape[0], step))


def _rasterize(points: np.ndarray, cells: np.ndarray, material: np.ndarray, shape,
               labels: np.ndarray | None = None):
    """Which pixel centres the elements cover.

    Returns flat arrays over the pixels: whether some element covers it, and (without
    `labels`) the material of the last one; with `labels`, instead, how many covering
    elements disagree with the label of their pixel. Elements are bucketed by their
    bounding box, each axis rounded up to a power of two, and tested in batches of a few
    million candidate centres.
    """
    d = len(shape)
    n_pix = math.prod(shape)
    covered = np.zeros(n_pix, bool)
    last = np.full(n_pix, -1, np.int64) if labels is None else None
    n_wrong = 0
    for start in range(0, len(cells), _CELLS_PER_CHUNK):
        cc = cells[start:start + _CELLS_PER_CHUNK]
        mat = material[start:start + _CELLS_PER_CHUNK]
        p = points[cc]  # (m, d+1, d)
        lo = np.maximum(np.ceil(p.min(axis=1) - 0.5 - _TOL).astype(np.int64), 0)
        hi = np.minimum(np.floor(p.max(axis=1) - 0.5 + _TOL).astype(np.int64), np.array(shape) - 1)
        extent = hi - lo + 1  # (m, d) pixel centres per axis in the bounding box
        edges = p[:, 1:] - p[:, :1]  # (m, d, d), rows are edge vectors
        det = _det(edges)
        ok = (extent > 0).all(axis=1) & (np.abs(det) > _TOL)
        side = np.left_shift(1, np.ceil(np.log2(np.maximum(extent, 1))).astype(np.int64))  # (m, d)
        bucket = np.ravel_multi_index(tuple(np.log2(side).astype(np.int64).T), (64,) * d)
        for b in np.unique(bucket[ok]):
            box = tuple(int(x) for x in np.unravel_index(b, (64,) * d))
            box = tuple(1 << x for x in box)
            offsets = np.stack(np.unravel_index(np.arange(math.prod(box)), box), axis=1)
            members = np.flatnonzero(ok & (bucket == b))
            step = max(1, _CANDIDATES_PER_CHUNK // len(offsets))
            for s0 in range(0, len(members), step):
                e = members[s0:s0 + step]
                inv = _inv(edges[e])
                pix = lo[e, None, :] + offsets[None]  # (n, box, d)
                inbox = (pix <= hi[e, None, :]).all(axis=-1)
                lam = np.einsum("nkd,nde->nke", pix + 0.5 - p[e, None, 0, :], inv)  # barycentric 1..d
                inside = inbox & (lam >= -_TOL).all(axis=-1) & (lam.sum(axis=-1) <= 1 + _TOL)
                which, k = np.nonzero(inside)
                flat = np.ravel_multi_index(tuple(pix[which, k].T), shape)
                mats = mat[e[which]]
                covered[flat] = True
                if labels is None:
                    last[flat] = mats
                else:
                    n_wrong += int(np.count_nonzero(mats != _at(labels, flat)))
    return covered, last, n_wrong


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
        Where elements of different materials cover one pixel centre, one of them wins.

    Examples
    --------
    >>> from napari_swa_imesh.mesh._imesh import mesh_labels
    >>> lab = np.array([[1, 0], [2, 2]])
    >>> rasterize_materials(mesh_labels(lab, exclude=[0])).tolist()
    [[1, -1], [2, 2]]
    """
    covered, last, _ = _rasterize(_index_points(mesh), mesh.cells, mesh.material,
                                  tuple(mesh.shape))
    last[~covered] = fill
    return last.reshape(mesh.shape)


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
        del key, sorted_key
    else:
        # two int64 keys: all columns but the last packed, then the last
        head = np.zeros(len(rows), np.int64)
        for j in range(k - 1):
            head = head * n + rows[:, j]
        order = np.lexsort((rows[:, -1], head))
        sorted_head, sorted_last = head[order], rows[order, -1]
        new = np.r_[True, (sorted_head[1:] != sorted_head[:-1]) | (sorted_last[1:] != sorted_last[:-1])]
        del head, sorted_head, sorted_last
    group_sorted = np.cumsum(new) - 1
    inverse = np.empty(len(rows), np.int64)
    inverse[order] = group_sorted
    counts = np.bincount(group_sorted)
    return inverse, counts


def _facet_passes(sorted_cells: np.ndarray, n_points: int):
    """Yield (facets (F, d) sorted ids, opposite (F,)) in passes over ranges of the lowest id.

    A facet of a cell whose ids are sorted is that cell without one column, still sorted;
    every copy of a facet has the same lowest id, so each pass sees all copies of its
    facets and memory stays bounded by ``_FACETS_PER_PASS``.
    """
    n_vert = sorted_cells.shape[1]
    n_pass = max(1, -(-len(sorted_cells) * n_vert // _FACETS_PER_PASS))
    bounds = np.linspace(0, n_points, n_pass + 1).astype(np.int64)
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        facets, opposite = [], []
        for i in range(n_vert):
            lowest = sorted_cells[:, 1 if i == 0 else 0]
            sel = np.flatnonzero((lowest >= lo) & (lowest < hi))
            facets.append(np.delete(sorted_cells[sel], i, axis=1))
            opposite.append(sorted_cells[sel, i])
        yield np.concatenate(facets), np.concatenate(opposite)


def _side(points, facets, opposite) -> np.ndarray:
    """Sign of the opposite vertex relative to the facet with its vertices in sorted order."""
    out = np.empty(len(facets))
    for start in range(0, len(facets), _CELLS_PER_CHUNK):
        f = facets[start:start + _CELLS_PER_CHUNK]
        base = points[f[:, 0]]
        a = points[f[:, 1]] - base
        c = points[opposite[start:start + _CELLS_PER_CHUNK]] - base
        if points.shape[1] == 2:
            out[start:start + len(f)] = np.sign(a[:, 0] * c[:, 1] - a[:, 1] * c[:, 0])
        else:
            b = points[f[:, 2]] - base
            out[start:start + len(f)] = np.sign(np.einsum("fi,fi->f", a, np.cross(b, c)))
    return out


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


def check_mesh(mesh: Mesh, labels, *, exclude=(), tree: RegionTree | None = None) -> MeshChecks:
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
    tree : RegionTree, optional
        The region tree of `labels` (``build_tree(labels)``) when the caller has it
        already; built here otherwise.

    Returns
    -------
    MeshChecks
        Flags ``conforming``, ``positive_volume``, ``volume_sum``, ``inside_one_leaf``,
        ``labels_recovered``, ``finite`` and ``all_passed``, and the numbers behind them
        (see :class:`MeshChecks`).

    Raises
    ------
    TypeError
        For a `mesh` that is not a Mesh, or a `tree` that is not a RegionTree.
    ValueError
        For labels that are not a 2-D or 3-D label image of the mesh's dimension, or a
        `tree` built from an image of another shape.

    Notes
    -----
    Works in chunks (elements, and facets in passes over vertex-id ranges), so memory stays
    at a few hundred MB beyond the mesh itself plus one byte per pixel; time is
    O(M log M) plus one barycentric test per pixel centre in each element's bounding box.

    Examples
    --------
    >>> from napari_swa_imesh.mesh._imesh import mesh_labels
    >>> lab = np.array([[1, 1], [1, 2]])
    >>> check_mesh(mesh_labels(lab), lab).all_passed
    True
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"expected a napari_swa_imesh Mesh; got {type(mesh).__name__}.")
    lab = as_labels(labels, min_ndim=2, max_ndim=3)
    d = lab.ndim
    if mesh.ndim != d:
        raise ValueError(f"a {d}-D label image needs a {d}-D mesh of {d + 1}-vertex cells; got points "
                         f"{mesh.points.shape} and cells {mesh.cells.shape}.")
    exclude_arr = np.asarray(list(exclude) if not np.isscalar(exclude) else [exclude], dtype=np.int64)
    if tree is not None:
        if not isinstance(tree, RegionTree):
            raise TypeError(f"tree must be a RegionTree (from build_tree); got {type(tree).__name__}.")
        multiple = len(tree.shape) == lab.ndim and all(
            t % n == 0 for t, n in zip(tree.shape, lab.shape))
        if not multiple:
            raise ValueError(f"tree was built from an image of shape {tuple(tree.shape)}, but the "
                             f"labels have shape {lab.shape}; pass build_tree(labels) or no tree.")
    return _check_mesh(mesh, lab, exclude_arr, tree)


def _check_mesh(mesh: Mesh, lab: np.ndarray, exclude: np.ndarray,
                tree: RegionTree | None = None) -> MeshChecks:
    """The worker behind :func:`check_mesh`: `lab` from ``as_labels``, `exclude` int64,
    `tree` the region tree of `lab` or None (then built here)."""
    points = _index_points(mesh)
    # int32 ids halve the memory of the facet arrays (4 per tetrahedron)
    cells = np.asarray(mesh.cells, dtype=np.int32 if len(mesh.points) < 2**31 else np.int64)
    n_excluded = count_excluded(lab, exclude)
    voxel = float(np.prod(mesh.spacing)) if mesh.spacing else 1.0
    if tree is None:
        tree = _build_tree(labels_on_lattice(lab, _index_points(mesh)))
    # a tree on a finer lattice (anisotropy subdivision, refinement) is in lattice cells
    cells_per_voxel = np.array(tree.shape) // np.array(lab.shape)
    leaf_points = points if (cells_per_voxel == 1).all() else points * cells_per_voxel
    parts = {
        "n_unused_points": _unused_points(cells, len(points)),
        **_volumes(points, cells, lab.size - n_excluded, voxel),
        **_facets(points, cells, lab, exclude),
        **_leaves(leaf_points, cells, tree),
        **_pixels(points, cells, mesh.material, lab, exclude, n_excluded),
        **_finite(mesh),
    }
    return MeshChecks(**{name: parts[name] for name in MeshChecks.__dataclass_fields__})


def _unused_points(cells: np.ndarray, n_points: int) -> int:
    used = np.zeros(n_points, dtype=bool)
    used[cells.ravel()] = True
    return int(n_points - np.count_nonzero(used))


def _volumes(points, cells, n_included: int, voxel: float) -> dict:
    """Positive volumes that add up to the included pixels (computed in pixel units)."""
    vol = signed_volumes(points, cells)
    total = float(vol.sum())
    return {"min_volume": float(vol.min() * voxel) if vol.size else 0.0,
            "positive_volume": bool((vol > _TOL).all()),
            "volume_error": (total - n_included) * voxel,
            "volume_sum": abs(total - n_included) <= 1e-9 * max(1, n_included)}


def _facets(points, cells, lab: np.ndarray, exclude: np.ndarray) -> dict:
    """Facets shared by at most two cells, from opposite sides; the rest on the boundary."""
    box = np.array(lab.shape, dtype=float)
    shared_3plus = misoriented = off_box = unmatched = 0
    for facets, opposite in _facet_passes(np.sort(cells, axis=1), len(points)):
        inverse, counts = _group_rows(facets)
        per_occurrence = counts[inverse]
        shared_3plus += int((counts >= 3).sum())
        twice = np.flatnonzero(per_occurrence == 2)
        side_sum = np.bincount(inverse[twice], weights=_side(points, facets[twice], opposite[twice]),
                               minlength=len(counts))
        misoriented += int(((counts == 2) & (side_sum != 0)).sum())
        once = np.flatnonzero(per_occurrence == 1)
        del inverse, per_occurrence, twice
        fpts = points[facets[once]]  # (B, d, d)
        on_box = ((np.abs(fpts).max(axis=1) <= _TOL) |
                  (np.abs(fpts - box).max(axis=1) <= _TOL)).any(axis=1)
        off = once[~on_box]
        off_box += len(off)
        # a boundary facet inside the box must face an excluded pixel
        normal = _outward_normal(points, facets[off], opposite[off])
        probe = fpts[~on_box].mean(axis=1) + 0.25 * normal
        pix = np.floor(probe).astype(np.int64)
        in_image = ((pix >= 0) & (pix < np.array(lab.shape))).all(axis=1)
        probe_included = np.zeros(len(pix), dtype=bool)
        probe_included[in_image] = ~_excluded(lab[tuple(pix[in_image].T)], exclude)
        unmatched += int((probe_included | ~np.isfinite(normal).all(axis=1)).sum())
    return {"n_facets_shared_3plus": shared_3plus, "n_misoriented_facets": misoriented,
            "n_boundary_facets_off_box": off_box, "n_unmatched_facets": unmatched,
            "conforming": shared_3plus == 0 and misoriented == 0 and unmatched == 0}


def _leaves(points, cells, tree: RegionTree) -> dict:
    """Every element inside one maximal homogeneous block: the leaf under its centroid."""
    find = leaf_finder(tree)
    shape = np.array(tree.shape)
    outside = 0
    for start in range(0, len(cells), _CELLS_PER_CHUNK):
        corner_pts = points[cells[start:start + _CELLS_PER_CHUNK]]  # (m, d+1, d)
        centroid = np.floor(corner_pts.mean(axis=1)).astype(np.int64)
        in_image = ((centroid >= 0) & (centroid < shape)).all(axis=1)
        leaf = np.zeros(len(corner_pts), dtype=np.intp)
        leaf[in_image] = find(centroid[in_image])
        lo = tree.origin[leaf][:, None, :]
        hi = lo + tree.size[leaf][:, None, None]
        inside = ((corner_pts >= lo - _TOL) & (corner_pts <= hi + _TOL)).all(axis=(1, 2)) & in_image
        outside += int((~inside).sum())
    return {"n_outside_leaf": outside, "inside_one_leaf": outside == 0}


def _pixels(points, cells, material, lab: np.ndarray, exclude: np.ndarray,
            n_excluded: int) -> dict:
    """The label image recovered at pixel centres, excluded pixels left uncovered."""
    covered, _, n_wrong_hits = _rasterize(points, cells, material, lab.shape, labels=lab)
    uncovered = np.flatnonzero(np.logical_not(covered, out=covered))
    del covered
    excluded_uncovered = int(np.count_nonzero(_excluded(_at(lab, uncovered), exclude)))
    missed = len(uncovered) - excluded_uncovered
    covered_excluded = n_excluded - excluded_uncovered
    wrong = missed + covered_excluded + n_wrong_hits
    return {"n_pixels_wrong": wrong, "labels_recovered": wrong == 0}


def _finite(mesh: Mesh) -> dict:
    """A NaN compares false everywhere above, so it must fail on its own."""
    bad = int(np.count_nonzero(~np.isfinite(mesh.points)))
    for values in mesh.cell_data.values():
        values = np.asarray(values)
        if values.dtype.kind in "fc":
            bad += int(np.count_nonzero(~np.isfinite(values)))
    return {"n_nonfinite_values": bad, "finite": bad == 0}
