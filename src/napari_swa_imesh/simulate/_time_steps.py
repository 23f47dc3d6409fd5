"""Adaptive time steps for ``M du/dt + K u = 0`` (fixed values held): implicit Euler with
step doubling.

Each step is taken once with ``dt`` and twice with ``dt / 2``. Implicit Euler is first
order, so the error of the two half steps is about their difference from the one full
step: that difference is the step's error estimate, and the value kept is the Richardson
extrapolation ``2 u_half - u_full`` (second order; its amplification ``2 / (1 - z/2)^2 -
1 / (1 - z)`` is bounded by 1 on the negative axis and vanishes at infinity, so stiff
modes are damped as implicit Euler damps them, and each of the two solves keeps the
amount ``int c u`` of an insulated box, so the extrapolation keeps it too).

Control is per step: a step is accepted when its estimate is at most ``tol / STABILITY``.
Errors do not add up from step to step in a parabolic problem: the heat equation damps
them, and for implicit Euler the error at ``t_N`` is bounded by the largest local error
times the stability factor ``L_N = 1 + sqrt(log(t_N / k_N))`` (Eriksson and Johnson,
SIAM J. Numer. Anal. 28, 1991, for this scheme as dG(0)); that product is the
time-error estimate reported at each saved time. It bounds the first-order half-step
solution; the extrapolated one kept is more accurate still. At ``t = 0`` the field jumps (a
fixed face, a released material), so the first steps are very short (a per-unit-step
control would need tens of thousands of them: measured 84k for a slab); the controller
grows them by doubling as the field smooths, geometrically.

Step sizes are dyadic fractions of the base step, ``dt = base / 2**j``: a saved time is
always a step's end, and there are few distinct systems ``M / dt + K``, each with its
multigrid hierarchy built once and kept while it is in use (:data:`CACHED_SYSTEMS`).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ._solve import SPDSolver

__all__ = ["FINEST_LEVEL", "StepRecord", "adaptive_euler"]

#: Shortest step: ``base / 2**FINEST_LEVEL`` (about 1e-9 of the base step).
FINEST_LEVEL = 30
#: Systems (and multigrid hierarchies) kept at once: the controller uses levels j and
#: j + 1 and moves one level at a time.
CACHED_SYSTEMS = 4
#: A step is doubled when its estimate is below this share of its allowance: doubling
#: multiplies a first-order local error by 4.
GROW = 0.2
#: The stability factor the per-step allowance leaves room for (``L_N`` is 2.7 for
#: ``t_N / k_N = 20``, a geometric step sequence's ratio).
STABILITY = 3.0


@dataclass
class StepRecord:
    """What the integrator did up to one saved time.

    Attributes
    ----------
    time : float
    values : (n,) ndarray
        The field (all dofs) at `time`.
    previous : (n,) ndarray
        The field one step earlier (for the time derivative at `time`).
    step : float
        The last step's length.
    time_error : float
        Largest step estimate since ``t = 0`` times the stability factor ``L_N``
        (absolute, the field's units).
    steps, rejected, iterations : int
        Accepted steps, rejected tries and CG iterations since ``t = 0``.
    """

    time: float
    values: np.ndarray
    previous: np.ndarray
    step: float
    time_error: float
    steps: int
    rejected: int
    iterations: int
    capped: bool = False


class _Systems:
    """``(M_ff / dt + K_ff)`` solvers by level, the least recently used dropped."""

    def __init__(self, mass_ff, stiff_ff, base: float, tol: float, coarse):
        self.mass_ff, self.stiff_ff, self.base = mass_ff, stiff_ff, base
        self.tol, self.coarse = tol, coarse
        self.cache: OrderedDict[int, SPDSolver] = OrderedDict()
        self.setup_seconds = 0.0

    def solver(self, level: int) -> SPDSolver:
        if level in self.cache:
            self.cache.move_to_end(level)
            return self.cache[level]
        dt = self.base / 2.0 ** level
        # the mass term keeps the system definite: a part with no fixed face is well posed
        system = (self.mass_ff * (1.0 / dt) + self.stiff_ff).tocsr()
        solver = SPDSolver(system, tol=self.tol, overwrite=True, coarse=self.coarse)
        self.setup_seconds += solver.setup_seconds
        self.cache[level] = solver
        while len(self.cache) > CACHED_SYSTEMS:
            self.cache.popitem(last=False)
        return solver

    def step(self, u_f: np.ndarray, level: int, load: np.ndarray) -> tuple[np.ndarray, int]:
        """One implicit Euler step of ``base / 2**level`` from `u_f` (free dofs)."""
        dt = self.base / 2.0 ** level
        x, info = self.solver(level).solve(self.mass_ff @ u_f / dt - load, u_f)
        return x, info.iterations


def _blocks(mass, stiffness, free: np.ndarray, fixed_values: np.ndarray):
    mass_ff = mass[free][:, free].tocsr()
    stiff_rows = stiffness[free]
    stiff_ff = stiff_rows[:, free].tocsr()
    # the fixed values are held from t = 0 on (the start has them), so their mass terms
    # cancel and only their stiffness coupling loads the free dofs
    load = stiff_rows[:, ~free] @ fixed_values if fixed_values.size else \
        np.zeros(int(free.sum()))
    return mass_ff, stiff_ff, np.asarray(load).ravel()


def adaptive_euler(mass: sparse.csr_matrix, stiffness: sparse.csr_matrix, u: np.ndarray,
                   free: np.ndarray, *, base: float, saves: list[int], duration: float,
                   tol: float, solver_tol: float, coarse=None, max_steps: int = 20000
                   ) -> Iterator[StepRecord]:
    """Integrate from `u` (fixed dofs already at their values), yielding each saved time.

    Parameters
    ----------
    mass, stiffness : (n, n) csr_matrix
    u : (n,) ndarray
        The start; not modified.
    free : (n,) ndarray of bool
        Dofs without a fixed value.
    base : float
        The longest step; saved times are whole multiples of it.
    saves : list of int
        Saved times as multiples of `base`, increasing.
    duration : float
        The run's end time.
    tol : float
        Absolute time-error allowance (the field's units): each step's estimate is kept
        within ``tol / STABILITY``. 0: no control, every step is `base` (plain implicit
        Euler, no extrapolation; the estimate is still computed, with one more solve).
    solver_tol : float
        Relative residual of the linear solves.
    coarse : sparse matrix, optional
        The multigrid's first coarse space restricted to the free dofs (P2).
    max_steps : int
        Accepted steps after which the controller stops shortening them (the run then
        finishes at the current step length and :attr:`StepRecord.capped` is set).

    Yields
    ------
    StepRecord
    """
    mass_ff, stiff_ff, load = _blocks(mass, stiffness, free, u[~free])
    systems = _Systems(mass_ff, stiff_ff, base, solver_tol, coarse)
    u = u.copy()
    u_f = u[free].copy()
    previous = u_f.copy()
    unit = 1 << FINEST_LEVEL                       # a base step in finest steps
    position, level, last_dt = 0, 0, base
    worst, steps, rejected, iterations, capped = 0.0, 0, 0, 0, False
    allowed = tol / STABILITY
    if tol > 0:
        level = min(FINEST_LEVEL - 1, 8)           # the start jumps: begin short
    for save in saves:
        end = save * unit
        while position < end:
            size = 1 << (FINEST_LEVEL - level)     # this step in finest steps
            dt = base / 2.0 ** level
            full, n1 = systems.step(u_f, level, load)
            half, n2 = systems.step(u_f, level + 1, load)
            half, n3 = systems.step(half, level + 1, load)
            iterations += n1 + n2 + n3
            difference = float(np.abs(half - full).max(initial=0.0))
            if tol <= 0:
                # fixed steps keep the full step, whose error is about twice the difference
                new, estimate = full, 2.0 * difference
            else:
                estimate = difference
                if estimate > allowed and level + 1 < FINEST_LEVEL and not capped:
                    rejected += 1
                    # first order: the estimate falls with dt^2
                    level = min(FINEST_LEVEL - 1, level + max(1, math.ceil(
                        0.5 * math.log2(estimate / allowed))))
                    continue
                new = 2.0 * half - full
            previous, u_f = u_f, new
            position += size
            worst = max(worst, estimate)
            steps += 1
            last_dt = dt
            if tol > 0 and steps >= max_steps:
                capped = True
            if (tol > 0 and level > 0 and position % (2 * size) == 0
                    and (capped or estimate <= GROW * allowed)):
                level -= 1
        stability = 1.0 + math.sqrt(max(0.0, math.log(save * base / last_dt)))
        time_error = stability * worst
        u[free] = u_f
        before = u.copy()
        before[free] = previous
        yield StepRecord(save * base, u.copy(), before, last_dt, time_error, steps,
                         rejected, iterations, capped)

