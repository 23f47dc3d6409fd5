"""The certified interval's settings and checks: its target, its refinement's limits."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Real

import numpy as np

from ..mesh import Mesh
from ._adapt import MAX_REFINE
from ._assembly import Space, fe_space
from ._budget import estimate_memory, format_bytes, unknowns
from ._curl import BYTES_PER_CURL_NODE, CURL_NODES, CurlBound, curl_bound
from ._dual import DualBound, FacetTable, dual_bound, facet_table
from ._stream import StreamBound, stream_bound

__all__ = ["CERTIFY_UNKNOWNS", "GAP_TARGET", "GRADED_SHARE", "GRADED_UNKNOWNS", "Refinement",
           "cannot_refine", "check_gap", "check_memory_budget", "flux_scale",
           "grades", "keep_sharper", "lower_bound", "plan_refinement", "relative_gaps",
           "sharpen_interval"]

#: Default relative width ``(upper - lower) / lower`` of the certified interval: wider, the
#: run refines where the gap is (while the refine levels and the memory budget allow).
GAP_TARGET = 0.02
#: Most unknowns a mesh refined for the interval may take, per dimension (besides the
#: memory budget): time, not memory, is what a small 3-D image at refine 2-4 runs out of
#: first (a 256^2 checkerboard closes to 1.3 % at 0.99M P2 unknowns; a 3-D P2 row is
#: about three times as long).
CERTIFY_UNKNOWNS = {2: 1_200_000, 3: 300_000}
#: Share of the gap (the hypercircle indicator) that must lie in elements no wider than a
#: voxel for the graded step: there one split per level reaches the staircase's corners.
#: Elsewhere (a checkerboard's flat squares, one leaf each) it cannot within the refine
#: levels (a 256^2 board stayed at 37 % after three splits), so interface refinement
#: takes every corner at once.
GRADED_SHARE = 0.9
#: Unknowns the graded steps aim the finest refine level at: each step grows the mesh by
#: the same factor, so the last level left lands there (3-D: the curl's space, beyond
#: which the sharper lower bound is not computed; counted in P2 nodes whatever the order).
GRADED_UNKNOWNS = {2: 400_000, 3: int(0.9 * CURL_NODES)}
#: Least growth of a graded step worth its solves.
GRADED_GROWTH = 1.2


def check_gap(gap) -> float:
    """The interval's target relative width, or ValueError."""
    if isinstance(gap, bool) or not isinstance(gap, Real) or not gap > 0:  # type: ignore[operator]
        raise ValueError(f"gap must be a positive relative width (0.02 for 2 %; inf never "
                         f"refines), not {gap!r}.")
    return float(gap)


def check_memory_budget(memory) -> None:
    if isinstance(memory, bool) or not isinstance(memory, Real) or not memory > 0:  # type: ignore[operator]
        raise ValueError(f"memory must be a positive number of bytes, not {memory!r}.")


def relative_gaps(interval: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """Per axis ``(upper - lower) / lower`` (infinite for a zero lower bound)."""
    return {a: 0.0 if hi <= lo else (hi - lo) / lo if lo > 0 else float("inf")
            for a, (lo, hi) in interval.items()}


def flux_scale(lo: np.ndarray, hi: np.ndarray, axis: int) -> float:
    """``A / L`` of the box along `axis`: the flux of a unit k_eff."""
    return float(np.prod(np.delete(hi - lo, axis)) / (hi[axis] - lo[axis]))


def cannot_refine(mesh: Mesh, labels, level: int) -> str | None:
    """Why the labels cannot be meshed again at interface refinement `level` for the
    interval (None: they can)."""
    if labels is None or isinstance(labels, Mesh):
        return "a mesh is not meshed again (simulate the label image to refine it)"
    if mesh.recipe is None or not mesh.recipe.remeshable:
        return "this mesh cannot be refined (not a template mesh of the labels)"
    if level > MAX_REFINE:
        return f"the finest refine level ({MAX_REFINE}) is reached"
    return None




def lower_bound(mesh: Mesh, space: Space, p1_space: Space, tensors: np.ndarray,
                cell_material: np.ndarray, axis: int, lo: np.ndarray, hi: np.ndarray, *,
                tol: float, facets: FacetTable | None = None,
                memory: float = float("inf"), upper: float = float("inf"),
                gap: float = 0.0, sharpen: bool = True) -> DualBound | StreamBound | CurlBound:
    """The sharpest lower bound of k_eff along `axis` this mesh allows.

    2-D: the stream function on the primal's elements (:mod:`._stream`; with P2 the mixed
    RT1 bound, as sharp as the primal's P2 upper bound). 3-D, or a 2-D mesh whose
    boundary the stream function cannot take: the Crouzeix-Raviart / RT0 flux
    (:mod:`._dual`), in 3-D improved by the curl of a P2 vector field (:mod:`._curl`)
    while that space has at most :data:`._curl.CURL_NODES` nodes and its peak fits the
    memory budget with the run's own estimate. Every result has
    ``k_lower``, ``info`` and ``hypercircle``.

    Parameters
    ----------
    mesh : Mesh
    space : Space
        The primal's space (P1 or P2).
    p1_space : Space
        The P1 space of `mesh` (the Crouzeix-Raviart bound's geometry).
    tensors, cell_material, axis, lo, hi, tol, facets
        As for :func:`._dual.dual_bound`.
    memory : float
        The run's memory budget in bytes.
    upper, gap : float
        The primal's k_eff and the target relative width: a 3-D Crouzeix-Raviart bound
        already within `gap` of `upper` is kept (the curl costs several primal solves).
    sharpen : bool
        False: no curl in 3-D (a mesh the interval will grade further, :func:`grades`,
        needs the gap's place, not its sharpest value).

    Returns
    -------
    DualBound, StreamBound or CurlBound
    """
    facets = facet_table(mesh.cells) if facets is None else facets
    bound = stream_bound(mesh, space, tensors, cell_material, axis, lo, hi, tol=tol,
                         facets=facets)
    if bound is not None:
        return bound
    base = dual_bound(mesh, p1_space, tensors, cell_material, axis, lo, hi, tol=tol,
                      facets=facets)
    if (mesh.ndim != 3 or not sharpen or not base.k_lower > 0
            or upper <= base.k_lower * (1 + gap)):
        return base
    if space.order == 2:
        p2 = space
    else:                       # one P2 space per mesh, so the curl's matrix is shared
        p2 = facets.cache.get("p2") or facets.cache.setdefault("p2", fe_space(mesh, 2))
    need = BYTES_PER_CURL_NODE * p2.n_dofs + estimate_memory(mesh, space.order, True)
    if p2.n_dofs > CURL_NODES or need > memory:
        return base
    better = curl_bound(mesh, p2, tensors, cell_material, axis, lo, hi, base, facets)
    return base if better is None else better


@dataclass(frozen=True)
class Refinement:
    """The next mesh the interval asks for (:func:`plan_refinement`).

    Attributes
    ----------
    why : str or None
        Why there is none (a clause for the warning); None: refine.
    level : int
        The refine level of its finest elements (interface elements of ``2**-level``
        voxels).
    target : float or None
        Graded: the most vertices the next mesh may have (:func:`._adapt.refine_within`
        splits the leaves of largest gap within them). None: interface refinement at
        `level`.
    leaf_gap : (L,) ndarray or None
        The gap per balanced leaf, for the graded step.
    """

    why: str | None
    level: int
    target: float | None = None
    leaf_gap: np.ndarray | None = None

    @property
    def message(self) -> str:
        where = "where the gap is largest" if self.target is not None else "at interfaces"
        return f"meshing the labels again with elements of 2^-{self.level} voxels {where}"


def voxel_share(mesh: Mesh, indicator: np.ndarray) -> float:
    """Share of `indicator` (one value per element) in elements no wider than a voxel
    along every axis (1 for an indicator summing to zero)."""
    total = float(indicator.sum())
    if not total > 0:
        return 1.0
    spacing = np.asarray(mesh.spacing, dtype=float) if mesh.spacing else np.ones(mesh.ndim)
    corners = mesh.points[mesh.cells]                                   # (M, d+1, d)
    width = (corners.max(axis=1) - corners.min(axis=1)) / spacing       # (M, d) voxels
    small = (width <= 1 + 1e-9).all(axis=1)
    return float(indicator[small].sum()) / total


def plan_refinement(mesh: Mesh, labels, level: int, gap: np.ndarray, *, order: int,
                    may_refine: bool, growth_seen: float, memory: float,
                    interval: bool, graded: bool = False) -> Refinement:
    """How to mesh the labels again for a wide interval, or why not.

    Graded (by the Prager-Synge gap per element, `gap`) when the mesh still has a refine
    level left and :data:`GRADED_SHARE` of the gap lies in elements no wider than a voxel:
    the leaves of largest gap are split once, as many as grow the vertices by the factor
    that reaches :data:`GRADED_UNKNOWNS` at the finest level. The gap is guaranteed and
    local, so the unknowns go to the voxel corners and edges where both bounds converge
    slowly (64^2 blobs at contrast 100: 2.4 % with 255k P2 unknowns graded, 3.0 % with
    438k by interface refinement). Otherwise interface refinement at `level` (the
    refine-until-closes loop's count), checked against :data:`CERTIFY_UNKNOWNS` and
    `memory` with the growth `growth_seen` of its last level.

    Parameters
    ----------
    mesh : Mesh
        The mesh whose interval is wide.
    labels : array_like of int or Mesh
        What the run was given (a mesh is not meshed again).
    level : int
        The next interface refinement level.
    gap : (M,) ndarray
        The gap per element of `mesh`.
    order : int
        The element order.
    may_refine : bool
        False when the mesh was asked as it is.
    growth_seen : float
        Growth of the elements at the last interface level (1 before one).
    memory : float
        The run's budget in bytes.
    interval : bool
        Whether the dual is solved (it counts in the memory estimate).
    graded : bool
        Whether `mesh` came from a graded step (interface refinement is then asked at a
        level above its finest).

    Returns
    -------
    Refinement
    """
    why = cannot_refine(mesh, labels, level)       # a mesh input says so first
    if why is None and not may_refine:
        why = ("adapt was given, so the mesh is kept as asked (leave adapt to auto to "
               "refine for the interval)")
    if why is not None:
        return Refinement(why, level)
    now = _lattice_level(mesh)
    if graded and level <= now:    # not interface refinement at a level graded already
        level = now + 1
        why = cannot_refine(mesh, labels, level)
        if why is not None:
            return Refinement(why, level)
    grow = _graded_growth(mesh, order)
    if grow >= GRADED_GROWTH and voxel_share(mesh, gap) >= GRADED_SHARE:
        leaf = np.asarray(mesh.cell_data["leaf"])
        return Refinement(None, now + 1, len(mesh.points) * grow, np.bincount(leaf, gap))
    # predicted before meshing (a refine-4 mesh of a small 3-D image took minutes to
    # make): the growth of the last level, at least 2^(d-1) (interfaces are d-1 dim.)
    growth = max(growth_seen, 2.0 ** (mesh.ndim - 1))
    cap = CERTIFY_UNKNOWNS[mesh.ndim]
    if unknowns(mesh, order) * growth > cap:
        return Refinement(f"the next refinement would take about "
                          f"{unknowns(mesh, order) * growth:,.0f} unknowns, above the "
                          f"{cap:,} the interval's refinement may take (pass --refine to "
                          "go further)", level)
    need = estimate_memory(mesh, order, interval) * growth
    if need > memory:
        return Refinement(f"the next refinement would need about {format_bytes(need)}, "
                          f"above the memory budget of {format_bytes(memory)} (raise it "
                          "with --memory)", level)
    return Refinement(None, level)


def grades(mesh: Mesh, labels, may_refine: bool) -> bool:
    """Whether a wide interval on the 3-D `mesh` would be graded again (a refine level
    left, the growth to :data:`GRADED_UNKNOWNS` at least :data:`GRADED_GROWTH`): its
    lower bound is then the Crouzeix-Raviart one, whose hypercircle places the gap as
    well, and the curl (several primal solves) is left to the last mesh
    (:func:`sharpen_interval` when the step is not taken after all)."""
    if mesh.ndim != 3 or not may_refine or cannot_refine(mesh, labels, 0) is not None:
        return False
    return _graded_growth(mesh, 2) >= GRADED_GROWTH


def _lattice_level(mesh: Mesh) -> int:
    """The refine level of `mesh`'s lattice (the finest, :data:`MAX_REFINE`, without one)."""
    lattice = None if mesh.recipe is None else mesh.recipe.lattice
    return MAX_REFINE if lattice is None else int(lattice.refine)


def _graded_growth(mesh: Mesh, order: int) -> float:
    """The growth of the vertices per graded step that reaches :data:`GRADED_UNKNOWNS`
    (of `order`, P2 in 3-D) at the finest refine level (1 with no level left)."""
    now = _lattice_level(mesh)
    if now >= MAX_REFINE:
        return 1.0
    per_vertex = unknowns(mesh, order if mesh.ndim == 2 else 2) / len(mesh.points)
    aim = GRADED_UNKNOWNS[mesh.ndim] / per_vertex
    return max(aim / len(mesh.points), 1.0) ** (1.0 / (MAX_REFINE - now))


def keep_sharper(lower: float, earlier: tuple[float, float] | None) -> float:
    """The larger of a lower bound and an earlier mesh's (None: none): both bound the
    same k_eff, that of the labels (every IMESH mesh of them places the materials
    exactly), so the sharper holds for the finer mesh too, where its lower bound may be
    the Crouzeix-Raviart flux alone (a curl space too large to build)."""
    return lower if earlier is None else max(lower, earlier[0])


def sharpen_interval(interval: dict, info: dict, wide: Mapping[str, float], mesh: Mesh,
                     space: Space, p1_space: Space, tensors: np.ndarray,
                     cell_material: np.ndarray, image_axes: Mapping[str, int],
                     lo: np.ndarray, hi: np.ndarray, *, tol: float, facets: FacetTable,
                     memory: float, gap: float) -> dict[str, float]:
    """The curl's lower bound on the last mesh, for the axes still `wide`, when the mesh
    was solved for grading (:func:`grades`) but is not graded after all.

    Parameters
    ----------
    interval, info : dict
        Per axis name the interval and the dual's solver info (updated in place).
    wide : mapping of str to float
        The axes whose relative gap is above `gap`.
    mesh, space, p1_space, tensors, cell_material, lo, hi, tol, facets, memory
        As for :func:`lower_bound`.
    image_axes : mapping of str to int
        Mesh axis of each axis name.
    gap : float
        The target relative width.

    Returns
    -------
    dict of str to float
        The axes still wider than `gap`, with their gaps.
    """
    for name in wide:
        low, value = interval[name]
        dual = lower_bound(mesh, space, p1_space, tensors, cell_material, image_axes[name],
                           lo, hi, tol=tol, facets=facets, memory=memory, upper=value,
                           gap=gap)
        if dual.k_lower > low:
            interval[name], info[name] = (min(dual.k_lower, value), value), dual.info
    return {a: g for a, g in relative_gaps({a: interval[a] for a in wide}).items() if g > gap}
