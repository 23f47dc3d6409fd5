"""Subdivision factors for anisotropic voxels: the fewest cells per voxel within a
residual-aspect limit, and the quality bound at each aspect.

Spacings are read as the rational numbers they mean: the ratios of the voxel sizes (and
the limit) are taken as the simplest fractions within :data:`RATIO_TOLERANCE` and every
aspect is compared exactly, so float32 header values and 1e-6 noise never change the
factors. :mod:`._lattice` builds the lattice from them.
"""

from __future__ import annotations

import functools
import itertools
import math
from fractions import Fraction

import numpy as np

__all__ = ["ASPECT_LIMIT", "MAX_FACTOR", "RATIO_TOLERANCE", "aspect_bounds", "aspect_table",
           "check_max_aspect", "lattice_choices", "subdivision_factors"]

#: Default largest residual aspect of the lattice cells: the 3-D bounds there are
#: radius-to-edge 1.3754 and dihedral angles 29.50-131.47 degrees (1.3185 and 30.5-130.3
#: at 1.2, 1.4349 and 28.5 at 1.3; see :func:`aspect_bounds`). 5/4 is the largest simple
#: aspect keeping ratio <= 1.40 and dihedral angles >= 29 degrees, and it takes the most
#: common clinical MR spacing, 0.9375 x 0.9375 x 1.5, with 2 cells per voxel instead of 12.
ASPECT_LIMIT = 1.25
#: Relative tolerance within which spacing ratios (and `max_aspect`) are read as the
#: simplest fraction: 5x the 1e-6 noise of an affine's column norms, 300x float32 rounding.
RATIO_TOLERANCE = 5e-6
#: Largest subdivision of a voxel along one axis (spacing aspect up to 16 x max_aspect).
MAX_FACTOR = 16


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


def check_max_aspect(max_aspect, name: str = "max_aspect", *, subdivide: bool = True) -> float:
    """`max_aspect` as a float >= 1, or ValueError naming it (`name`) and what it trades;
    also when there is no subdivision (`subdivide` False) for it to bound."""
    if not subdivide:
        raise ValueError(f"{name} bounds the cells anisotropic voxels are cut into; with no "
                         "subdivision (--no-subdivide, subdivide=False) there are none: give "
                         "one or the other.")
    if isinstance(max_aspect, bool) or not isinstance(max_aspect, (int, float, np.integer,
                                                                   np.floating)) \
            or not (math.isfinite(float(max_aspect)) and float(max_aspect) >= 1.0):
        raise ValueError(f"{name} must be a finite number >= 1 (the largest residual "
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
    rows: list[dict] = []
    below: float | None = None
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
