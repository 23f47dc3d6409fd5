"""The lattice the mesher works on: voxels subdivided for anisotropic spacing and for
refinement at material interfaces, and leaves split to a size cap.

Why a lattice
-------------
The templates' quality bounds hold for cubic lattice cells. A voxel of spacing
(2.5, 1, 1) stretches every template by 2.5 along one axis (worst radius-to-edge 3.66).
Subdividing each voxel into ``n_a`` cells along axis ``a`` (integers) brings the
*residual aspect* ``max(h) / min(h)`` of the cell size ``h = spacing / n`` under a limit
``max_aspect`` (default :data:`ASPECT_LIMIT`), where the bounds of :func:`aspect_bounds`
hold; of the factors that do, the fewest cells per voxel are taken (elements grow with
them). The tree merges the cells again wherever the labels are uniform, so the interior
stays coarse. Material boundaries stay on voxel faces, which are lattice planes, so every
material keeps its exact volume.

Spacings are read as the rational numbers they mean: the ratios of the voxel sizes are
taken as the simplest fractions within :data:`RATIO_TOLERANCE` (a float32 header's
0.800000011920929 is 4/5) and every aspect is compared exactly, so float32 rounding and
noise of 1e-6 never change the lattice, and equal cell counts are told apart by a rule
that permutes with the axes.

Refinement ``K`` divides every cell by ``2**K`` more and splits every leaf that shares a
facet with a material interface down to one lattice cell: elements at interfaces are
``2**-K`` voxels, the interior coarsens as before, and balance and templates are the
same (so are the bounds).

A size cap ``H`` splits every leaf whose longest possible element edge (its body
diagonal) is longer than ``H``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..._region_tree import PAD_LABEL, RegionTree, _build_tree
from ._subdivision import (
    ASPECT_LIMIT,
    MAX_FACTOR,
    RATIO_TOLERANCE,
    aspect_bounds,
    aspect_table,
    check_max_aspect,
    lattice_choices,
    subdivision_factors,
)

__all__ = ["ASPECT_LIMIT", "MAX_FACTOR", "MAX_REFINE", "RATIO_TOLERANCE", "Lattice",
           "aspect_bounds", "aspect_table", "check_max_aspect", "choose_lattice",
           "labels_on_lattice", "lattice_choices", "lattice_tree", "subdivision_factors"]

#: Largest interface refinement level: 2**-4 voxels (4096 cells per voxel in 3-D).
MAX_REFINE = 4


@dataclass(frozen=True)
class Lattice:
    """How voxels are cut into lattice cells.

    Attributes
    ----------
    spacing : tuple of float
        Voxel size per axis (physical units).
    factors : tuple of int
        Cells per voxel along each axis from the anisotropy subdivision (all 1 for cubic
        voxels or when subdivision is off).
    refine : int
        Interface refinement level K: cells are a further ``2**K`` times smaller.
    max_aspect : float or None
        The residual-aspect limit `factors` were chosen for (None: not subdivided).
    """

    spacing: tuple[float, ...]
    factors: tuple[int, ...]
    refine: int = 0
    max_aspect: float | None = ASPECT_LIMIT

    @property
    def ndim(self) -> int:
        return len(self.spacing)

    @property
    def cells_per_voxel(self) -> tuple[int, ...]:
        """Lattice cells per voxel along each axis: ``factors * 2**refine``."""
        return tuple(int(n) << self.refine for n in self.factors)

    @property
    def step(self) -> tuple[float, ...]:
        """Physical size of one lattice cell per axis."""
        return tuple(s / f for s, f in zip(self.spacing, self.cells_per_voxel))

    @property
    def residual_aspect(self) -> float:
        """``max(step) / min(step)``: how far the lattice cells are from cubes."""
        return max(self.step) / min(self.step)

    @property
    def is_voxel_lattice(self) -> bool:
        """Whether lattice cells are the voxels themselves (no subdivision, no refinement)."""
        return self.refine == 0 and all(n == 1 for n in self.factors)

    def describe(self) -> dict:
        """Plain-data summary for reports and ``--json``."""
        return {"factors": list(self.factors), "refine": self.refine,
                "max_aspect": self.max_aspect,
                "cells_per_voxel": list(self.cells_per_voxel),
                "step": [float(s) for s in self.step],
                "residual_aspect": float(self.residual_aspect),
                "bounds": aspect_bounds(self.ndim, self.residual_aspect)}


def choose_lattice(spacing, *, refine: int = 0, subdivide: bool = True,
                   max_aspect: float | None = None) -> Lattice:
    """The lattice for voxels of `spacing`: anisotropy subdivision and interface refinement.

    Parameters
    ----------
    spacing : tuple of float
        Voxel size per axis (already checked).
    refine : int
        Interface refinement level, ``0 .. MAX_REFINE``: cells at interfaces at most
        ``2**-refine`` voxels along every axis. The subdivision counts toward it: voxels
        cut into at least ``2**j`` cells along every axis take ``j`` levels fewer
        (``Lattice.refine``), instead of multiplying the cells again.
    subdivide : bool
        Subdivide anisotropic voxels so the bounds of :func:`aspect_bounds` at
        `max_aspect` hold in physical space. Off: voxels are stretched templates and no
        bound is claimed beyond the stretched one.
    max_aspect : float, optional
        Largest residual aspect of the cells (default :data:`ASPECT_LIMIT`): larger gives
        fewer cells per voxel and a looser bound (``swa-imesh bounds --spacing`` prints
        the choices). Not with ``subdivide=False``.

    Examples
    --------
    >>> choose_lattice((3.0, 1.0, 1.0), refine=1).cells_per_voxel
    (6, 2, 2)
    >>> choose_lattice((1.0, 0.8, 1.2), refine=2).cells_per_voxel    # 2 x 2 x 3, one level
    (4, 4, 6)
    """
    refine = check_refine(refine)
    if max_aspect is not None and not subdivide:
        raise ValueError("max_aspect bounds the subdivided cells; with subdivide=False "
                         "(--no-subdivide) the voxels are meshed as they are, so give one "
                         "or the other.")
    max_aspect = ASPECT_LIMIT if max_aspect is None else check_max_aspect(max_aspect)
    factors = (subdivision_factors(spacing, max_aspect=max_aspect) if subdivide
               else (1,) * len(spacing))
    # every axis has at least 2**j cells already: j levels of the refinement are there
    refine = max(0, refine - (min(factors).bit_length() - 1))
    return Lattice(tuple(float(s) for s in spacing), factors, refine,
                   max_aspect if subdivide else None)


def check_level(value, name: str, top: int, meaning: str) -> int:
    """`value` as an int in ``0 .. top``, or ValueError naming it and what it means."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
            or not 0 <= int(value) <= top:
        raise ValueError(f"{name} must be a whole number from 0 to {top} ({meaning}); got "
                         f"{value!r}.")
    return int(value)


def check_refine(refine) -> int:
    """`refine` as an int from 0 to ``MAX_REFINE``, or ValueError saying what to pass."""
    return check_level(refine, "refine", MAX_REFINE,
                       "elements at interfaces are 2^-refine voxels")


# ----------------------------------------------------------------------------- the tree


def lattice_tree(lab: np.ndarray, lattice: Lattice, *, exclude: np.ndarray,
                 max_size: float | None = None, periodic: bool = False) -> RegionTree:
    """The region tree of `lab` on the lattice, refined at interfaces and capped in size.

    Parameters
    ----------
    lab : ndarray of int
        Checked label image (``as_labels``).
    lattice : Lattice
        From :func:`choose_lattice` for the image's spacing.
    exclude : ndarray of int64
        Materials left out of the mesh: interfaces between two of them are not refined.
    max_size : float, optional
        Longest element edge allowed (physical units); leaves whose body diagonal is
        longer are split.
    periodic : bool
        Split every leaf that touches the image box down to one lattice cell. Cells of
        one cell are always cut the same way (Kuhn), so opposite faces of the box then
        carry the same vertices and facets, translated: what periodic conditions need.

    Returns
    -------
    RegionTree
        Leaves in lattice cells (``shape`` is the image shape times the cells per voxel).
        For the voxel lattice and no cap, the tree of `lab` itself.
    """
    sub = lab
    for axis, n in enumerate(lattice.factors):
        if n > 1:
            sub = np.repeat(sub, n, axis=axis)
    tree = _build_tree(sub)
    del sub
    k = lattice.refine
    if k:
        tree = finer_tree(tree, k)
        faces = _InterfaceFaces(lab, exclude)
        cells = np.asarray(lattice.cells_per_voxel, dtype=np.int64)
        tree = split_leaves(tree, lambda origin, size: faces.touches(origin, size, cells))
    if periodic:
        tree = split_box_faces(tree)
    if max_size is not None:
        diagonal = float(np.linalg.norm(lattice.step))
        # a leaf of side 2^l cells has edges up to 2^l diagonals long (its Kuhn diagonal)
        tree = split_leaves(tree, lambda origin, size: size * diagonal > max_size)
    return tree


def finer_tree(tree: RegionTree, k: int) -> RegionTree:
    """The same leaves on a lattice 2^k times finer (each leaf 2^k cells wider)."""
    return RegionTree(tree.origin << k, (tree.level + k).astype(np.int8), tree.label,
                      tuple(n << k for n in tree.shape),
                      tuple(n << k for n in tree.padded_shape), tree.top_level + k)


def split_box_faces(tree: RegionTree) -> RegionTree:
    """Every leaf touching the image box split down to one lattice cell. Cells of one
    cell are always cut the same way (Kuhn), so opposite faces of the box then carry the
    same vertices and facets, translated: what periodic conditions need."""
    extent = np.asarray(tree.shape, dtype=np.int64)
    return split_leaves(tree, lambda origin, size: (
        (origin == 0) | (origin + size[:, None] >= extent)).any(axis=1))


def split_leaves(tree: RegionTree, want) -> RegionTree:
    """Split leaves into their 2^d children, recursively, while ``want(origin, size)``.

    `want` gets the origins (L, d) and sides (L,) of the leaves still in question and
    returns which to split; padding leaves and leaves of one cell are never split.
    """
    d = tree.ndim
    corners = np.array(list(itertools.product((0, 1), repeat=d)), dtype=np.int64)
    done_origin, done_level, done_label = [], [], []
    origin, level, label = tree.origin, tree.level, tree.label
    while len(level):
        split = (level >= 1) & (label != PAD_LABEL)
        idx = np.flatnonzero(split)
        if idx.size:
            size = np.left_shift(np.int64(1), level[idx].astype(np.int64))
            split[idx] = np.asarray(want(origin[idx], size), dtype=bool)
        done_origin.append(origin[~split])
        done_level.append(level[~split])
        done_label.append(label[~split])
        if not split.any():
            break
        half = np.left_shift(np.int64(1), level[split].astype(np.int64) - 1)
        origin = (origin[split][:, None, :] + corners[None] * half[:, None, None]).reshape(-1, d)
        level = np.repeat(level[split] - 1, len(corners)).astype(np.int8)
        label = np.repeat(label[split], len(corners))
    return RegionTree(np.concatenate(done_origin), np.concatenate(done_level),
                      np.concatenate(done_label), tree.shape, tree.padded_shape,
                      tree.top_level)


class _InterfaceFaces:
    """Which voxel faces lie between two different labels (one of them meshed), with
    summed-area tables so any rectangle of faces is counted in O(2^(d-1))."""

    def __init__(self, lab: np.ndarray, exclude: np.ndarray):
        self.shape = np.asarray(lab.shape, dtype=np.int64)
        d = lab.ndim
        meshed = ~np.isin(lab, exclude) if exclude.size else None
        self.tables = []
        for a in range(d):
            lo = [slice(None)] * d
            hi = [slice(None)] * d
            lo[a], hi[a] = slice(None, -1), slice(1, None)
            faces = lab[tuple(lo)] != lab[tuple(hi)]
            if meshed is not None:
                faces &= meshed[tuple(lo)] | meshed[tuple(hi)]
            # planes 0 .. n_a along a (the box sides carry no interface), a zero row and
            # column in front along every other axis for the summed-area table
            pad = [(1, 1) if b == a else (1, 0) for b in range(d)]
            counts = np.pad(faces, pad).astype(np.int32)
            del faces
            for b in range(d):
                if b != a:
                    np.cumsum(counts, axis=b, out=counts)
            self.tables.append(counts)

    def touches(self, origin: np.ndarray, size: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """(L,) bool: the leaf (lattice origin, side) shares a facet with an interface."""
        d = origin.shape[1]
        hit = np.zeros(len(origin), dtype=bool)
        hi_corner = origin + size[:, None]
        vlo = np.minimum(origin // cells, self.shape)                    # voxel ranges
        vhi = np.minimum(-(-hi_corner // cells), self.shape)
        for a in range(d):
            table = self.tables[a]
            for plane in (origin[:, a], hi_corner[:, a]):
                on_face = (plane % cells[a] == 0) & ~hit
                rows = np.flatnonzero(on_face)
                if not rows.size:
                    continue
                c = plane[rows] // cells[a]
                total = np.zeros(len(rows), dtype=np.int64)
                # inclusion-exclusion over the other axes' ranges [vlo, vhi) of voxels;
                # table index i+1 holds the sum over voxels < i+1 (zero row in front)
                others = [b for b in range(d) if b != a]
                for picks in itertools.product((0, 1), repeat=len(others)):
                    index = [None] * d
                    index[a] = c
                    sign = 1
                    for b, p in zip(others, picks):
                        index[b] = vhi[rows, b] if p else vlo[rows, b]
                        sign = -sign if not p else sign
                    total += sign * table[tuple(index)]
                hit[rows] = total > 0
        return hit


def labels_on_lattice(lab: np.ndarray, points: np.ndarray, *, factors=None,
                      spacing=None) -> np.ndarray:
    """The labels repeated by the anisotropy subdivision a mesh was cut with.

    Anisotropic voxels are cut into ``n`` cells per axis: the blocks a mesh's elements
    must lie in are then homogeneous blocks of those cells, which a tree of the voxels
    does not have (refinement by ``2**K`` along every axis needs no repeat: the tree of
    labels repeated ``2**K`` times is the voxels' tree scaled).

    Parameters
    ----------
    lab : ndarray
        The label image.
    points : (N, d) ndarray
        The mesh's points in voxel units.
    factors : sequence of int, optional
        The subdivision the mesh records (``recipe.lattice.factors``).
    spacing : sequence of float, optional
        Without `factors` (a mesh read from a file): the voxel spacing. The subdivision
        the mesher chooses for it is used when every point lies on its lattice, else none.
    """
    if factors is None:
        factors = (1,) * lab.ndim
        if spacing is not None and len(points):
            try:
                guess = subdivision_factors(spacing)
            except ValueError:
                guess = factors
            fine = np.asarray(guess, dtype=float) * 2.0 ** (MAX_REFINE + 4)
            scaled = points * fine
            if np.abs(scaled - np.rint(scaled)).max() <= 1e-6 * max(1.0, np.abs(scaled).max()):
                factors = guess
    for axis, n in enumerate(factors):
        if int(n) > 1:
            lab = np.repeat(lab, int(n), axis=axis)
    return lab
