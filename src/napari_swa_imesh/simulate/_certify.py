"""The certified interval's settings and checks: its target, its refinement's limits."""

from __future__ import annotations

from collections.abc import Mapping
from numbers import Real

import numpy as np

from ..mesh import Mesh
from ._adapt import MAX_REFINE
from ._assembly import Space, fe_space
from ._budget import estimate_memory
from ._curl import BYTES_PER_CURL_NODE, CURL_NODES, CurlBound, curl_bound
from ._dual import DualBound, FacetTable, dual_bound, facet_table
from ._stream import StreamBound, stream_bound

__all__ = ["CERTIFY_UNKNOWNS", "GAP_TARGET", "cannot_refine", "check_gap",
           "check_memory_budget", "flux_scale", "lower_bound", "relative_gaps"]

#: Default relative width ``(upper - lower) / lower`` of the certified interval: wider, the
#: run refines where the gap is (while the refine levels and the memory budget allow).
GAP_TARGET = 0.02
#: Most unknowns a mesh refined for the interval may take, per dimension (besides the
#: memory budget): time, not memory, is what a small 3-D image at refine 2-4 runs out of
#: first (a 256^2 checkerboard closes to 1.3 % at 0.99M P2 unknowns; a 3-D P2 row is
#: about three times as long).
CERTIFY_UNKNOWNS = {2: 1_200_000, 3: 300_000}


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
                gap: float = 0.0) -> DualBound | StreamBound | CurlBound:
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
    if mesh.ndim != 3 or not base.k_lower > 0 or upper <= base.k_lower * (1 + gap):
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
