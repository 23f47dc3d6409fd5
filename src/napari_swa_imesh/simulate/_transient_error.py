"""Error control of a transient run: the estimate it reports, and what it does when the
estimate is over what was asked (mesh again where the estimate is largest, or say so).

The estimate's parts (space by the P2 elliptic reconstruction at the saved times, time as
the sum of the step-doubling estimates) are computed in :mod:`._transient_space` and
:mod:`._time_steps`; this module keeps the record and the decisions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh import Mesh


def _plain(value: float):
    return None if not np.isfinite(value) else float(value)

#: Asked max error of a transient run, as a share of the largest jump of the data.
DEFAULT_ERROR = 0.01
#: Share of the asked error given to space (the mesh); the rest goes to time.
SPACE_SHARE = 0.75
#: Times a label image is meshed again where the space estimate is largest, when it is
#: over its share of the asked error after the a priori mesh (each reruns the steps).
POSTERIORI_ROUNDS = 2
#: Most saved times the space error is estimated at (one P2 solve each).
ESTIMATED_TIMES = 12


@dataclass
class ErrorEstimate:
    """Estimated errors of a transient run, at the saved times.

    Attributes
    ----------
    space : (T,) ndarray
        ``max |w - u|`` of the P2 elliptic reconstruction (NaN where not estimated).
    time : (T,) ndarray
        Sum of the step estimates up to each saved time.
    jump : float
        Largest difference of the data (fixed and initial values): the errors' scale.
    asked : float or None
        The asked error (share of `jump`); None for fixed steps.
    steps, rejected : int
        Time steps taken and tries rejected.
    refined : int
        Times the labels were meshed again where the space estimate was largest.
    """

    space: np.ndarray
    time: np.ndarray
    jump: float
    asked: float | None
    steps: int
    rejected: int
    refined: int = 0

    def total(self) -> np.ndarray:
        """(T,) space plus time estimate (absolute)."""
        return np.nan_to_num(self.space, nan=0.0) + self.time

    def relative(self) -> float:
        """Largest total estimate over the saved times, as a share of `jump` (NaN when
        the space error was estimated nowhere)."""
        if self.jump == 0:
            return 0.0
        if self.space.size > 1 and np.all(np.isnan(self.space[1:])):
            return float("nan")
        return float(self.total().max() / self.jump)

    def summary(self) -> dict:
        """Plain JSON (NaN as None)."""
        def plain(a):
            return [None if not np.isfinite(v) else float(v) for v in a]
        return {"asked": self.asked, "estimate": _plain(self.relative()),
                "jump": self.jump, "space": plain(self.space), "time": plain(self.time),
                "time_steps": self.steps, "rejected_steps": self.rejected,
                "refined_by_estimate": self.refined}

    def describe(self) -> str:
        """One line for people."""
        if self.jump == 0:
            return "error: none (the data are uniform, so is the field)"
        worst = self.relative()
        space = np.nanmax(self.space) / self.jump if np.any(np.isfinite(self.space[1:])) \
            else float("nan")
        asked = "fixed steps" if self.asked is None else f"asked {100 * self.asked:g} %"
        if not np.isfinite(worst):
            return (f"estimated error: time {100 * self.time.max() / self.jump:.2g} % of "
                    f"the jump, space not estimated ({asked})")
        return (f"estimated max error {100 * worst:.2g} % of the jump (space "
                f"{100 * space:.2g} %, time {100 * self.time.max() / self.jump:.2g} %; "
                f"{asked})")


def _worth_refining(estimate: ErrorEstimate, plan, estimator, error) -> bool:
    """Whether to mesh again where the space estimate is largest and run again: a label
    image, an ask, and a space estimate over its share."""
    if plan is None or estimator is None or error is None or estimate.jump == 0:
        return False
    if getattr(estimator, "worst", None) is None:
        return False
    space = np.nanmax(estimate.space) if np.any(np.isfinite(estimate.space)) else 0.0
    return bool(space > SPACE_SHARE * error * estimate.jump)


def _refine_by_estimate(labels, mesh: Mesh, estimator, threshold: float, tree):
    """The labels meshed again with the leaves split where the elliptic reconstruction
    differs from the field by more than `threshold` (within the vertex budget), with its
    tree, or None and the reason nothing can be split."""
    from ._adapt import MAX_REFINE, refine_within
    from ._transient_space import VERTEX_FACTOR, _refine_level, vertex_budget

    if _refine_level(mesh) >= MAX_REFINE:
        return None, f"refine level {MAX_REFINE}, the finest"
    n = len(mesh.points)
    difference = np.abs(estimator.worst)
    vertex = difference[:n].copy()
    np.maximum.at(vertex, estimator.edges[:, 0], difference[n:])
    np.maximum.at(vertex, estimator.edges[:, 1], difference[n:])
    cell = vertex[mesh.cells].max(axis=1)
    leaf = np.asarray(mesh.cell_data["leaf"])
    per_leaf = np.zeros(int(leaf.max()) + 1)
    np.maximum.at(per_leaf, leaf, np.where(cell > threshold, cell, 0.0))
    budget = vertex_budget(labels)
    if not per_leaf.any():
        return None, "no element over the threshold"
    if n >= (1 - 0.05) * budget:
        return None, f"the vertex budget of {int(budget)}, {VERTEX_FACTOR:g} times the voxels'"
    new, tree = refine_within(labels, mesh, per_leaf, budget, tree)
    if len(new.points) <= n:
        return None, f"the vertex budget of {int(budget)}, {VERTEX_FACTOR:g} times the voxels'"
    return (new, tree), ""


def _edge_count(mesh: Mesh) -> int:
    """Edges of the mesh (P2's extra unknowns)."""
    cells = mesh.cells
    k = cells.shape[1]
    pairs = np.concatenate([np.sort(cells[:, [a, b]], axis=1)
                            for a in range(k) for b in range(a + 1, k)])
    return int(np.unique(pairs[:, 0].astype(np.int64) * (len(mesh.points) + 1)
                         + pairs[:, 1]).size)


def _estimate_indices(count: int) -> list[int]:
    """Saved times (indices) the space error is estimated at: all of them up to
    :data:`ESTIMATED_TIMES`, else the first, the last and geometrically spread others
    (the error is largest early, where the front is steepest)."""
    if count <= ESTIMATED_TIMES:
        return list(range(count))
    picks = np.unique(np.round(np.geomspace(1, count, ESTIMATED_TIMES)).astype(int) - 1)
    return sorted(set(picks.tolist()) | {0, count - 1})


def _error_warnings(estimate: ErrorEstimate, plan, record, order: int,
                    from_mesh: bool) -> list[str]:
    """One sentence per way the run may miss its asked error."""
    out: list[str] = []
    if estimate.jump == 0:
        return out
    worst = estimate.relative()
    asked = DEFAULT_ERROR if estimate.asked is None else estimate.asked
    if np.isfinite(worst) and worst > asked:
        if estimate.asked is None:
            fix = ("leave error at its default (the mesh and the time steps are then "
                   "chosen for it)")
        elif from_mesh:
            fix = ("the mesh file is too coarse for the earliest saved time: simulate the "
                   "label image (it is then meshed for the diffusion length) or mesh it "
                   "finer, or save later times (fewer --steps)")
        elif plan is not None and not plan.get("met", True):
            size = (f"; largest element {plan['max_ratio']:.2g} times the size the "
                    "diffusion length asks" if plan.get("max_ratio", 0) > 1 else "")
            fix = (f"the mesh could not be refined enough ({plan['reason']}{size}): save "
                   "later times (fewer --steps) or a smaller image")
        else:
            fix = "ask a looser error or save later times (fewer --steps)"
        out.append(f"the estimated error {100 * worst:.2g} % of the jump exceeds "
                   f"{100 * asked:g} %; {fix}.")
    if record is not None and record.capped:
        out.append("the time steps reached their budget before the asked accuracy, so the "
                   "time error may exceed its estimate; run a shorter duration or ask a "
                   "looser error.")
    return out

