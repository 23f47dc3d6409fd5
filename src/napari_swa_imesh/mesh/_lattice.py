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

import functools
import itertools
import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .._tree import PAD_LABEL, RegionTree, _build_tree

__all__ = ["ASPECT_LIMIT", "MAX_REFINE", "Lattice", "aspect_bounds", "aspect_table",
           "check_max_aspect", "choose_lattice", "labels_on_lattice", "lattice_choices",
           "lattice_tree", "subdivision_factors"]

#: Default largest residual aspect of the lattice cells: the 3-D bounds there are
#: radius-to-edge 1.3754 and dihedral angles 29.50-131.47 degrees (1.3185 and 30.5-130.3
#: at 1.2, 1.4349 and 28.5 at 1.3; see :func:`aspect_bounds`). 5/4 is the largest simple
#: aspect keeping ratio <= 1.40 and dihedral angles >= 29 degrees, and it takes the most
#: common clinical MR spacing, 0.9375 x 0.9375 x 1.5, with 2 cells per voxel instead of 12.
ASPECT_LIMIT = 1.25
#: Relative tolerance within which spacing ratios (and `max_aspect`) are read as the
#: simplest fraction: 5x the 1e-6 noise of an affine's column norms, 300x float32 rounding.
RATIO_TOLERANCE = 5e-6
#: Largest subdivision of a voxel along one axis (spacing aspect up to about 19).
MAX_FACTOR = 16
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


def aspect_bounds(dim: int, aspect: float) -> dict:
    """Quality bounds of the template mesh on lattice cells of residual aspect `aspect`.

    The worst radius-to-edge ratio and the angle range (dihedral in 3-D) over every
    template simplex, for every cell shape whose axes lie within a factor `aspect` of each
    other. The extremes lie where every axis is 1 or `aspect` (a grid of shapes in
    between gives nothing worse; tests check it), so those shapes are all evaluated.

    Parameters
    ----------
    dim : {2, 3}
    aspect : float
        ``max(cell size) / min(cell size)``, at least 1.

    Returns
    -------
    dict
        ``worst_ratio``, ``min_angle`` and ``max_angle`` (degrees; dihedral in 3-D).

    Examples
    --------
    >>> b = aspect_bounds(3, 1.0)
    >>> round(b["worst_ratio"], 4), round(b["min_angle"], 2), round(b["max_angle"], 2)
    (1.118, 35.26, 125.26)
    """
    from ._templates import template_quality

    if dim not in (2, 3):
        raise ValueError(f"bounds exist for 2-D and 3-D lattices; got dim={dim!r}.")
    aspect = float(aspect)
    if not (np.isfinite(aspect) and aspect >= 1.0):
        raise ValueError(f"aspect must be a finite number >= 1; got {aspect!r}.")
    lo_key, hi_key = ("min_dihedral", "max_dihedral") if dim == 3 else ("min_angle", "max_angle")
    worst, lo, hi = 0.0, 180.0, 0.0
    for shape in itertools.product((1.0, aspect), repeat=dim):
        q = template_quality(dim, shape)
        worst = max(worst, float(q["quality"].max()))
        lo = min(lo, float(np.nanmin(q[lo_key])))
        hi = max(hi, float(np.nanmax(q[hi_key])))
    return {"worst_ratio": worst, "min_angle": lo, "max_angle": hi}


def aspect_table(dim: int, aspects=(1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.5, 2.0, 3.0)) -> list[dict]:
    """:func:`aspect_bounds` for a list of residual aspects: rows of plain data.

    Examples
    --------
    >>> [round(r["worst_ratio"], 4) for r in aspect_table(3, (1.0, 1.2))]
    [1.118, 1.3185]
    """
    return [{"aspect": float(a), **aspect_bounds(dim, a)} for a in aspects]


def _aspect(values) -> float:
    return float(max(values) / min(values))


def check_max_aspect(max_aspect) -> float:
    """`max_aspect` as a float >= 1, or ValueError saying what it trades."""
    if isinstance(max_aspect, bool) or not isinstance(max_aspect, (int, float, np.integer,
                                                                   np.floating)) \
            or not (math.isfinite(float(max_aspect)) and float(max_aspect) >= 1.0):
        raise ValueError(f"max_aspect must be a finite number >= 1 (the largest residual "
                         f"aspect of the lattice cells; default {ASPECT_LIMIT}: larger means "
                         f"fewer elements and a looser bound); got {max_aspect!r}.")
    return float(max_aspect)


def _simplest_between(lo: Fraction, hi: Fraction) -> Fraction:
    """The fraction of smallest denominator in ``[lo, hi]`` (``0 < lo <= hi``), by the
    continued-fraction expansion both ends share."""
    whole = math.floor(lo)
    if whole == lo or whole + 1 <= hi:
        return Fraction(whole if whole == lo else whole + 1)
    return whole + 1 / _simplest_between(1 / (hi - whole), 1 / (lo - whole))


def _as_fraction(value: float) -> Fraction:
    """`value` as the simplest fraction within :data:`RATIO_TOLERANCE` of it."""
    v = Fraction(float(value))
    return _simplest_between(v * (1 - Fraction(RATIO_TOLERANCE)),
                             v * (1 + Fraction(RATIO_TOLERANCE)))


def _rational_ratios(spacing) -> tuple[Fraction, ...]:
    """Each voxel size over the smallest, as the fraction it means (1, 5/4, 3/2 for
    float32 0.8, 1, 1.2)."""
    s = [float(v) for v in spacing]
    if not all(math.isfinite(v) and v > 0 for v in s):
        raise ValueError(f"spacing must be positive and finite; got {tuple(s)}.")
    smallest = min(s)
    return tuple(_as_fraction(v / smallest) for v in s)


def _candidates(ratios: tuple[Fraction, ...], bound: Fraction, strict: bool):
    """Every factor tuple that is the fewest cells for its smallest cell: (factors, exact
    residual aspect) with aspect <= `bound` (< with `strict`), factors <= MAX_FACTOR.

    A tuple of fewest cells has some axis ``a`` with the smallest cell ``m = r_a / n_a``;
    every other axis then takes the fewest cells keeping ``r_i / n_i`` in ``[m, bound*m]``.
    Any admissible tuple is at least these factorwise, so the minimum over ``(a, n_a)``
    is the minimum over all tuples, and every tuple of that minimum is among them.
    """
    out = []
    for a, n_a in itertools.product(range(len(ratios)), range(1, MAX_FACTOR + 1)):
        m = ratios[a] / n_a
        factors = []
        for i, r in enumerate(ratios):
            if i == a:
                factors.append(n_a)
                continue
            n = max(1, math.ceil(r / (bound * m)))
            if strict and r / n == bound * m:
                n += 1
            if n > MAX_FACTOR or r / n < m:
                break
            factors.append(n)
        else:
            h = [r / n for r, n in zip(ratios, factors)]
            aspect = max(h) / min(h)
            if aspect < bound or (aspect == bound and not strict):
                out.append((tuple(factors), aspect))
    return out


def _best(ratios: tuple[Fraction, ...], candidates):
    """The fewest cells; then the smallest residual aspect; then, over the axes sorted by
    spacing, the smaller factors first. Axes of equal spacing have equal factors in any
    tuple of fewest cells (the larger of two can drop to the smaller), so this order
    permutes with the axes."""
    order = sorted(range(len(ratios)), key=lambda i: ratios[i])
    return min(candidates, key=lambda c: (math.prod(c[0]), c[1],
                                          tuple(c[0][i] for i in order)))


@functools.lru_cache(maxsize=256)
def _factors(ratios: tuple[Fraction, ...], bound: Fraction) -> tuple[int, ...] | None:
    candidates = _candidates(ratios, bound, strict=False)
    return _best(ratios, candidates)[0] if candidates else None


def subdivision_factors(spacing, *, max_aspect: float = ASPECT_LIMIT) -> tuple[int, ...]:
    """Fewest cells per voxel (product of integer factors) with residual aspect <= `max_aspect`.

    Spacing ratios and `max_aspect` are read as the simplest fractions within
    :data:`RATIO_TOLERANCE` and compared exactly, so float32 rounding and relative noise
    of 1e-6 give the same factors. Of equally few cells, the smallest residual aspect is
    taken, then the smaller factors on the finer axes.

    Parameters
    ----------
    spacing : sequence of float
        Voxel size per axis.
    max_aspect : float
        Largest ``max(h) / min(h)`` allowed for the cell size ``h = spacing / factors``.

    Returns
    -------
    tuple of int
        One factor per axis, each in ``1 .. MAX_FACTOR``; all 1 when the voxels already
        meet `max_aspect`.

    Raises
    ------
    ValueError
        When no factors up to :data:`MAX_FACTOR` reach `max_aspect` (spacing aspect above
        about ``16 * max_aspect``).

    Examples
    --------
    >>> subdivision_factors((2.5, 1.0, 1.0))          # cells 1.25 x 1 x 1
    (2, 1, 1)
    >>> subdivision_factors((0.9375, 0.9375, 1.5))    # cells 0.9375 x 0.9375 x 0.75
    (1, 1, 2)
    >>> subdivision_factors((1.0, 0.800000011920929, 1.2), max_aspect=1.0)   # float32 0.8
    (5, 4, 6)
    """
    max_aspect = check_max_aspect(max_aspect)
    ratios = _rational_ratios(spacing)
    factors = _factors(ratios, _as_fraction(max_aspect))
    if factors is None:
        s = tuple(float(v) for v in spacing)
        raise ValueError(
            f"voxel spacing {s} has aspect {_aspect(s):.3g}: no subdivision of up to "
            f"{MAX_FACTOR} cells per axis makes cells within aspect {max_aspect}; resample "
            "the image closer to cubic voxels, allow a larger max_aspect (--max-aspect), or "
            "pass subdivide=False (--no-subdivide) to mesh the stretched voxels without a "
            "bound."
        )
    return factors


def lattice_choices(spacing, *, max_rows: int = 8) -> list[dict]:
    """What each `max_aspect` gives for voxels of `spacing`: the trade-off of cells per
    voxel against the quality bound, fewest cells first.

    Each row is the subdivision of fewest cells for a range of `max_aspect`; the next row
    is the best with a strictly smaller residual aspect, until the cells are cubic, the
    factors run out, or `max_rows`.

    Parameters
    ----------
    spacing : sequence of float
        Voxel size per axis (2 or 3 axes).
    max_rows : int
        Most rows.

    Returns
    -------
    list of dict
        ``factors``, ``cells_per_voxel`` (their product), ``residual_aspect``,
        ``max_aspect_from`` (the smallest `max_aspect` choosing these factors: their
        residual aspect) and ``max_aspect_below`` (the largest, exclusive; None for the
        voxels themselves), ``bounds`` (:func:`aspect_bounds`) and
        ``interface_cells_per_voxel_face`` (lattice cells on one voxel face, averaged over
        the axes: the element count near interfaces grows about with it).

    Examples
    --------
    >>> [(r["factors"], round(r["residual_aspect"], 3))
    ...  for r in lattice_choices((0.9375, 0.9375, 1.5), max_rows=3)]
    [((1, 1, 1), 1.6), ((1, 1, 2), 1.25), ((2, 2, 3), 1.067)]
    """
    ratios = _rational_ratios(spacing)
    d = len(ratios)
    rows, below = [], None
    bound = max(ratios) / min(ratios)
    strict = False
    while len(rows) < max_rows:
        candidates = _candidates(ratios, bound, strict)
        if not candidates:
            break
        factors, aspect = _best(ratios, candidates)
        faces = sum(math.prod(f for b, f in enumerate(factors) if b != a)
                    for a in range(d)) / d
        rows.append({"factors": factors, "cells_per_voxel": math.prod(factors),
                     "residual_aspect": float(aspect), "max_aspect_from": float(aspect),
                     "max_aspect_below": below,
                     "bounds": aspect_bounds(d, float(aspect)),
                     "interface_cells_per_voxel_face": float(faces)})
        if aspect == 1:
            break
        bound, strict, below = aspect, True, float(aspect)
    return rows


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
    """`refine` as an int in ``0 .. MAX_REFINE``, or ValueError saying what to pass."""
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
        The subdivision the mesh records (``info["lattice"]["factors"]``).
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
