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

from ..._region_tree import RegionTree, _build_tree
from ..._validation import as_labels
from ..mesher._lattice import labels_on_lattice
from ..model._quality import _corner_det, _det
from ..model._types import Mesh
from ._chain_check import lattice_checks
from ._facets import _blocks, _runs, _side_passes

__all__ = ["MeshChecks", "check_mesh", "rasterize_materials"]

_TOL = 1e-9
_CANDIDATES_PER_CHUNK = 1 << 22
_CELLS_PER_CHUNK = 1 << 16      # small enough for the cache
_RASTER_CELLS = 1 << 20
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
        Inside every maximal homogeneous block the elements carry its label and their
        volumes add up to the block's (to nothing in an excluded block). With
        ``conforming`` (no overlap, no hole) this is the label image given back at every
        pixel centre, excluded pixels uncovered; :func:`rasterize_materials` paints it.
    finite : bool
        Every point coordinate and float value in ``cell_data`` is a number (NaN or inf
        means the spacing over- or underflowed).
    n_unused_points, n_facets_shared_3plus, n_misoriented_facets, n_boundary_facets_off_box,
    n_unmatched_facets, n_outside_leaf, n_nonfinite_values : int
        The counts behind the flags.
    n_pixels_wrong : int
        Pixels of the blocks where that fails (elements of another material, or volume
        missing or too much).
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
    for start in range(0, len(cells), _RASTER_CELLS):
        cc = cells[start:start + _RASTER_CELLS]
        mat = material[start:start + _RASTER_CELLS]
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
                # barycentric 1..d
                lam = np.einsum("nkd,nde->nke", pix + 0.5 - p[e, None, 0, :], inv)
                inside = inbox & (lam >= -_TOL).all(axis=-1) & (lam.sum(axis=-1) <= 1 + _TOL)
                which, k = np.nonzero(inside)
                flat = np.ravel_multi_index(tuple(pix[which, k].T), shape)
                mats = mat[e[which]]
                covered[flat] = True
                if labels is not None:
                    n_wrong += int(np.count_nonzero(mats != _at(labels, flat)))
                elif last is not None:               # no labels: the array to paint
                    last[flat] = mats
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
    >>> from napari_swa_imesh.mesh.mesher._imesh import mesh_labels
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


def check_mesh(mesh: Mesh, labels, *, exclude=(), tree: RegionTree | None = None,
               full: bool = False) -> MeshChecks:
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
    full : bool
        Pair every facet by a sort even for points on the lattice (see Notes); the same
        verdict and counts.

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
    Integer points in pixel units (every template mesh): one pass without a sort
    (``_chain_check``). Other meshes, one failing there, or `full`: one chunked pass over
    the elements (volumes, the block at both corners of each bounding box, per-block
    volumes) and one sort of integer facet keys (8 bytes per facet of an element, in
    passes beyond ``2**27`` keys); memory beyond the mesh is about the keys plus an int32
    block index per pixel, time O(M log M) with a small constant.

    Examples
    --------
    >>> from napari_swa_imesh.mesh.mesher._imesh import mesh_labels
    >>> lab = np.array([[1, 1], [1, 2]])
    >>> check_mesh(mesh_labels(lab), lab).all_passed
    True
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"expected a napari_swa_imesh Mesh; got {type(mesh).__name__}.")
    lab = as_labels(labels, min_ndim=2, max_ndim=3)
    d = lab.ndim
    if mesh.ndim != d:
        raise ValueError(f"a {d}-D label image needs a {d}-D mesh of {d + 1}-vertex cells; "
                         f"got points {mesh.points.shape} and cells {mesh.cells.shape}.")
    exclude_arr = np.asarray([exclude] if np.isscalar(exclude) else list(exclude), dtype=np.int64)
    if tree is not None:
        if not isinstance(tree, RegionTree):
            raise TypeError("tree must be a RegionTree (from build_tree); "
                            f"got {type(tree).__name__}.")
        multiple = len(tree.shape) == lab.ndim and all(
            t % n == 0 for t, n in zip(tree.shape, lab.shape))
        if not multiple:
            raise ValueError(f"tree was built from an image of shape {tuple(tree.shape)}, but the "
                             f"labels have shape {lab.shape}; pass build_tree(labels) or no tree.")
    return _check_mesh(mesh, lab, exclude_arr, tree, full=full)


def _check_mesh(mesh: Mesh, lab: np.ndarray, exclude: np.ndarray,
                tree: RegionTree | None = None, *, full: bool = False) -> MeshChecks:
    """The worker behind :func:`check_mesh`: `lab` from ``as_labels``, `exclude` int64,
    `tree` the region tree of `lab` (or of its lattice) or None (then built here)."""
    lattice = None if mesh.recipe is None else mesh.recipe.lattice
    if lattice is not None:
        return _check_on_lattice(mesh, lab, exclude, tree, lattice.factors, full)
    # a mesh read from a file does not say how its voxels were cut: the subdivision the
    # mesher picks for this spacing when the points fit it, else the voxels themselves
    checks = _check_on_lattice(mesh, lab, exclude, tree, None, full)
    if not checks.all_passed and mesh.spacing and len(set(mesh.spacing)) > 1:
        voxels = _check_on_lattice(mesh, lab, exclude, tree, (1,) * lab.ndim, full)
        if voxels.all_passed:
            return voxels
    return checks


def _check_on_lattice(mesh: Mesh, lab: np.ndarray, exclude: np.ndarray,
                      tree: RegionTree | None, factors, full: bool = False) -> MeshChecks:
    points = _index_points(mesh)
    cells = np.asarray(mesh.cells)
    # anisotropic voxels cut into n cells per axis: check in those cells, whose
    # homogeneous blocks hold the elements (refinement by 2^K needs no such change)
    lattice_lab = labels_on_lattice(lab, points, factors=factors, spacing=mesh.spacing or None)
    repeats = np.array(lattice_lab.shape) // np.array(lab.shape)
    if (repeats != 1).any():
        points = points * repeats
        lab = lattice_lab
    n_excluded = count_excluded(lab, exclude)
    if tree is None or tuple(tree.shape) != lab.shape:
        tree = _build_tree(lab)
    finite = _finite(mesh)
    parts = None if full or not finite["finite"] else lattice_checks(
        points, cells, np.asarray(mesh.material), lab, exclude, tree, lab.size - n_excluded)
    if parts is None:  # not on the lattice, or failed there: the sort says what is wrong
        parts, sign, spread_bits = _elements(points, cells, np.asarray(mesh.material), lab,
                                             exclude, tree, lab.size - n_excluded)
        parts.update(_facets(points, cells, sign, lab, exclude, spread_bits))
    voxel = float(np.prod(mesh.spacing)) / float(np.prod(repeats)) if mesh.spacing else 1.0
    for key in ("min_volume", "volume_error"):
        parts[key] *= voxel
    parts.update(finite)
    return MeshChecks(**{name: parts[name] for name in MeshChecks.__dataclass_fields__})


def _elements(points, cells, material, lab: np.ndarray, exclude: np.ndarray,
              tree: RegionTree, n_included: int) -> tuple[dict, np.ndarray, int]:
    """Volumes, leaves and labels, element by element in chunks (one gather of corners).

    * volumes positive, adding up to the included pixels;
    * every element inside one leaf: the pixels at the low and high corner of its
      bounding box belong to the same leaf (leaves are boxes, so all pixels between do);
    * labels: the elements inside each leaf carry its label and fill it exactly (their
      volumes add up to the leaf's; zero for an excluded leaf). With the facets checked
      (no overlap, no hole) this is the label image recovered at every pixel centre.

    Returns the flags and counts (volumes in pixel units, unused points too), the sign of
    each volume and the bits of the largest id difference in a cell (for the facet keys).
    """
    d = lab.ndim
    coords = [np.ascontiguousarray(points[:, a]) for a in range(d)]
    shape = lab.shape
    strides = [math.prod(shape[a + 1:]) for a in range(d)]
    leaf_map = tree.to_image(values=np.arange(len(tree)), fill=-1,
                             dtype=np.int32 if len(tree) < 2**31 else np.int64).reshape(-1)
    lab_flat = lab.reshape(-1)  # a copy only for a non-contiguous image
    m = len(cells)
    sign = np.empty(m, dtype=np.int8)
    leaf_volume = np.zeros(len(tree))
    wrong_leaf = np.zeros(len(tree), dtype=bool)
    total, min_volume, n_flat, outside = 0.0, math.inf, 0, 0
    used = np.zeros(len(points), dtype=bool)
    spread = 0
    for start in range(0, m, _CELLS_PER_CHUNK):
        ids = cells[start:start + _CELLS_PER_CHUNK]
        used[ids] = True
        spread = max(spread, _spread(ids))
        p = [[x[ids[:, k]] for x in coords] for k in range(d + 1)]  # p[corner][axis]: (n,)
        det = _corner_det(p)
        vol = det / math.factorial(d)
        sign[start:start + len(vol)] = np.sign(det)
        total += float(det.sum())  # exact for integer corners, whatever the chunks
        min_volume = min(min_volume, float(vol.min()))
        n_flat += int(np.count_nonzero(vol <= _TOL))
        # pixels at the low and high corner of the bounding box, flat (in place: the
        # chunk's temporaries are most of the time here)
        in_image = np.ones(len(vol), dtype=bool)
        flat_lo = np.zeros(len(vol), dtype=np.int64)
        flat_hi = np.zeros(len(vol), dtype=np.int64)
        for a in range(d):
            axis = [p[k][a] for k in range(d + 1)]
            lo, hi = np.minimum(axis[0], axis[1]), np.maximum(axis[0], axis[1])
            for x in axis[2:]:
                np.minimum(lo, x, out=lo)
                np.maximum(hi, x, out=hi)
            lo += _TOL
            np.floor(lo, out=lo)
            hi -= _TOL
            np.ceil(hi, out=hi)
            hi -= 1
            np.maximum(hi, lo, out=hi)
            in_image &= (lo >= 0) & (hi < shape[a])
            for bound, flat in ((lo, flat_lo), (hi, flat_hi)):
                np.clip(bound, 0, shape[a] - 1, out=bound)
                flat += bound.astype(np.int64) * strides[a]
        del p
        leaf = leaf_map[flat_lo]
        inside = in_image & (leaf == leaf_map[flat_hi])
        outside += len(vol) - int(np.count_nonzero(inside))
        leaf, flat_lo = leaf[inside], flat_lo[inside]
        if len(leaf):  # cells come leaf by leaf: add over the chunk's range of leaves only
            first = int(leaf.min())
            part = np.bincount(leaf - first, weights=vol[inside])
            leaf_volume[first:first + len(part)] += part
        wrong = material[start:start + len(vol)][inside] != lab_flat[flat_lo]
        wrong_leaf[leaf[wrong]] = True
    total /= math.factorial(d)
    size = tree.size ** d
    expected = np.where(tree.inside & ~_excluded(tree.label, exclude), size, 0)
    wrong_leaf |= np.abs(leaf_volume - expected) > 1e-9 * np.maximum(size, 1)
    n_wrong = int(size[wrong_leaf & tree.inside].sum())
    return {"min_volume": min_volume if m else 0.0, "positive_volume": n_flat == 0,
            "volume_error": total - n_included,
            "volume_sum": abs(total - n_included) <= 1e-9 * max(1, n_included),
            "n_outside_leaf": outside, "inside_one_leaf": outside == 0,
            "n_pixels_wrong": n_wrong, "labels_recovered": n_wrong == 0,
            "n_unused_points": int(len(points) - np.count_nonzero(used)),
            }, sign, max(1, spread.bit_length())


def _spread(ids: np.ndarray) -> int:
    """Largest id difference inside one cell of `ids`, column by column."""
    hi, lo = np.maximum(ids[:, 0], ids[:, 1]), np.minimum(ids[:, 0], ids[:, 1])
    for k in range(2, ids.shape[1]):
        np.maximum(hi, ids[:, k], out=hi)
        np.minimum(lo, ids[:, k], out=lo)
    hi -= lo
    return int(hi.max()) if len(hi) else 0


def _facets(points, cells, sign, lab: np.ndarray, exclude: np.ndarray,
            spread_bits: int) -> dict:
    """Facets shared by at most two cells, from opposite sides; the rest on the boundary.

    One sort of integer keys (:func:`._facets._side_passes`): a facet seen from both sides
    is a key ending in 0 followed by the same key ending in 1.
    """
    d = lab.ndim
    box = np.array(lab.shape, dtype=float)
    shared_3plus = misoriented = off_box = unmatched = 0
    for keys, packer in _side_passes(cells, sign, spread_bits, n_points=len(points)):
        once_parts = []
        for block in _blocks(keys, 1):
            k = keys[block]
            starts, counts = _runs(k, 1)
            shared_3plus += int(np.count_nonzero(counts >= 3))
            two = starts[counts == 2]
            misoriented += int(np.count_nonzero(k[two + 1] - k[two] != 1))
            once_parts.append(k[starts[counts == 1]])
        once = np.concatenate(once_parts) if once_parts else keys[:0]
        del keys
        fpts = points[np.stack(packer.decode(once, d), axis=1)]  # (B, d, d), ids sorted
        on_box = ((np.abs(fpts).max(axis=1) <= _TOL) |
                  (np.abs(fpts - box).max(axis=1) <= _TOL)).any(axis=1)
        off_box += int(np.count_nonzero(~on_box))
        fpts, seen_from = fpts[~on_box], (once[~on_box] & 1).astype(np.int8)
        # normal of the sorted facet; its cell lies on the side the key's bit says
        t = fpts[:, 1] - fpts[:, 0]
        normal = (np.stack([-t[:, 1], t[:, 0]], axis=1) if d == 2
                  else np.cross(t, fpts[:, 2] - fpts[:, 0]))
        normal *= (1 - 2 * seen_from)[:, None]                   # outward
        with np.errstate(divide="ignore", invalid="ignore"):
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        # a boundary facet inside the box must face an excluded pixel
        pix = np.floor(fpts.mean(axis=1) + 0.25 * normal).astype(np.int64)
        in_image = ((pix >= 0) & (pix < np.array(lab.shape))).all(axis=1)
        probe_included = np.zeros(len(pix), dtype=bool)
        probe_included[in_image] = ~_excluded(lab[tuple(pix[in_image].T)], exclude)
        unmatched += int((probe_included | ~np.isfinite(normal).all(axis=1)).sum())
    return {"n_facets_shared_3plus": shared_3plus, "n_misoriented_facets": misoriented,
            "n_boundary_facets_off_box": off_box, "n_unmatched_facets": unmatched,
            "conforming": shared_3plus == 0 and misoriented == 0 and unmatched == 0}


def _finite(mesh: Mesh) -> dict:
    """A NaN compares false everywhere above, so it must fail on its own."""
    bad = 0
    for values in (mesh.points, *mesh.cell_data.values()):
        values = np.asarray(values)
        # a finite sum proves every value finite (NaN and inf carry through a sum) at a
        # third of the cost of testing each; only a non-finite sum needs the count
        if values.dtype.kind in "fc" and not np.isfinite(values.sum()):
            bad += int(np.count_nonzero(~np.isfinite(values)))
    return {"n_nonfinite_values": bad, "finite": bad == 0}
