"""The time stepping of a reaction-diffusion run: linearly implicit, bounded, adaptive.

One step of length ``dt`` from ``u`` solves, with the lumped (row-sum) mass ``m`` and the
P1 stiffness ``K`` of the diffusivity,

    (m / dt + m a(u) + K) u' = m u / dt + m g(u) + f,

where the reaction is split into a part taken at the new time and a part at the old
one: Fisher-KPP ``rho u (1 - u) - k(t) u`` has ``a = rho u + k``, ``g = rho u`` (so
``rho u (1 - u')``, linear in ``u'``), the drug model ``-lambda u - k(t) u + s`` has
``a = lambda + k``, ``g = 0`` and the sources in ``f``. The matrix is symmetric positive
definite, and with a stiffness of non-positive off-diagonal entries (IMESH triangles of
square pixels; 3-D transition templates have obtuse dihedral angles, and the run says
so) an M-matrix: ``u' >= 0`` for ``u >= 0``, and for Fisher-KPP
``1 - u'`` solves the same system with a right-hand side ``m (1 - u) / dt + k m >= 0``,
so ``u'`` stays within ``[0, 1]`` for every step length (an implicit-explicit scheme
whose explicit part cannot overshoot).

**Error control.** Step doubling: the step is taken once with ``dt`` and twice with
``dt / 2``; ``max |u_half - u_full|`` estimates the local error and chooses the next
step (``dt * 0.9 sqrt(tol / est)``, within 0.2 .. 2 times), and the accepted value is the
Richardson extrapolation ``2 u_half - u_full`` (second order). The extrapolation may step
out of the bounds by about the local error: it is clipped, and the amount the clipping
changed is reported as its own term of the balance.

**Balance.** Summing the rows of each solve gives the change of the total amount
``sum m u`` exactly as growth ``dt sum m rho u (1 - u')``, kill ``-dt sum m k u'``, decay
``-dt sum m lambda u'``, sources ``dt sum f`` and the inflow through fixed values (the
residual of their rows); these terms are carried through the extrapolation, so the
residual of the balance is the solver's (tested to 1e-9 of the amount).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg

__all__ = ["BALANCE_TERMS", "GrowthStep", "Reaction", "imex_steps"]

#: The terms of the amount's balance, in the order the tables print them.
BALANCE_TERMS = ("growth", "kill", "decay", "sources", "boundary", "clipping")
#: Free unknowns up to which each step is solved by a sparse LU factorisation, per
#: dimension (2-D fill-in grows mildly, 3-D steeply); beyond, by conjugate gradients
#: preconditioned by the diagonal (the systems are well conditioned at the step lengths
#: a front allows: ``dt D / h^2`` of order 1).
DIRECT_LIMIT = {2: 400_000, 3: 40_000}
#: Most accepted plus rejected steps of one run.
MAX_STEPS = 200_000


@dataclass(frozen=True)
class Reaction:
    """The reaction of a run.

    Attributes
    ----------
    model : str
        ``"fisher-kpp"`` or ``"drug"``.
    rate : float
        Proliferation rate rho (Fisher-KPP).
    decay : float
        First-order uptake/decay lambda (drug).
    kill : tuple of (start, end, rate)
        Kill rates over time windows ``start <= t < end``, added where they overlap.
    """

    model: str
    rate: float = 0.0
    decay: float = 0.0
    kill: tuple[tuple[float, float, float], ...] = ()

    def kill_rate(self, t: float) -> float:
        """Sum of the kill rates of the windows holding `t`."""
        return float(sum(r for a, b, r in self.kill if a <= t < b))

    def breakpoints(self) -> list[float]:
        """Times where the kill rate jumps: the steps land on them."""
        return sorted({float(x) for a, b, _ in self.kill for x in (a, b)})


@dataclass
class GrowthStep:
    """The state after an accepted step.

    Attributes
    ----------
    time : float
    values : (n,) ndarray
        The field (a view the next step replaces: copy it to keep it).
    balance : dict of str to float
        The terms of :data:`BALANCE_TERMS`, summed from t = 0.
    steps, rejected : int
    stop : bool
        The step ended on one of the asked stop times.
    """

    time: float
    values: np.ndarray
    balance: dict[str, float]
    steps: int
    rejected: int
    stop: bool


class _System:
    """The free block of the stiffness and one step's solve."""

    def __init__(self, stiffness: sparse.csr_matrix, free: np.ndarray, ndim: int):
        self.free = free
        self.direct = DIRECT_LIMIT.get(ndim, DIRECT_LIMIT[3])
        k_free = stiffness[free][:, free].tocsr()
        k_free.sort_indices()
        self.k_free = k_free
        self.coupling = stiffness[free][:, ~free].tocsr()
        rows = np.repeat(np.arange(k_free.shape[0]), np.diff(k_free.indptr))
        self.diagonal = np.flatnonzero(rows == k_free.indices)      # (n_free,) positions
        if self.diagonal.size != k_free.shape[0]:
            raise ValueError("a vertex of the mesh has no diffusion: every meshed material "
                             "needs a positive diffusivity (exclude the others).")
        self.stiffness = stiffness

    def solve(self, diag: np.ndarray, rhs: np.ndarray, fixed_values: np.ndarray,
              guess: np.ndarray) -> np.ndarray:
        """The whole field with ``(K + diag) u = rhs`` on the free rows."""
        free = self.free
        matrix = self.k_free.copy()
        matrix.data[self.diagonal] += diag[free]
        b = rhs[free] - self.coupling @ fixed_values if fixed_values.size else rhs[free]
        if matrix.shape[0] <= self.direct:
            x = splinalg.splu(matrix.tocsc()).solve(b)
        else:
            inv = 1.0 / matrix.diagonal()
            x, info = splinalg.cg(matrix, b, x0=guess[free], rtol=1e-11, atol=0.0,
                                  maxiter=20 * int(np.sqrt(matrix.shape[0])) + 200,
                                  M=sparse.diags(inv))
            if info != 0:
                raise ArithmeticError("conjugate gradients did not converge")
        out = np.empty_like(rhs)
        out[free] = x
        out[~free] = fixed_values
        return out


def _one_step(system: _System, m: np.ndarray, load: np.ndarray, reaction: Reaction,
              u: np.ndarray, t: float, dt: float, fixed_values: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """(u', terms): one linearly implicit step and its balance terms (in BALANCE_TERMS
    order, clipping 0)."""
    kill = reaction.kill_rate(t + 0.5 * dt)      # steps never straddle a window's edge
    if reaction.model == "fisher-kpp":
        a, g = reaction.rate * u + kill, reaction.rate * u
    else:
        a, g = np.full_like(u, reaction.decay + kill), np.zeros_like(u)
    diag = m / dt + m * a
    rhs = m * u / dt + m * g + load
    new = system.solve(diag, rhs, fixed_values, u)
    free = system.free
    residual = (system.stiffness @ new + diag * new - rhs)[~free]
    terms = np.array([
        dt * float(np.sum(m * g * (1.0 - new))) if reaction.model == "fisher-kpp" else 0.0,
        -dt * kill * float(np.sum(m * new)),
        -dt * reaction.decay * float(np.sum(m * new)) if reaction.model == "drug" else 0.0,
        dt * float(np.sum(load[free])),
        dt * float(np.sum(residual)),
        0.0])
    return new, terms


def imex_steps(mass: np.ndarray, stiffness: sparse.csr_matrix, u: np.ndarray,
               free: np.ndarray, reaction: Reaction, *, stops: list[float], tol: float,
               scale: float, load: np.ndarray | None = None, first_step: float | None = None,
               upper: float | None = None, ndim: int = 3) -> Iterator[GrowthStep]:
    """Adaptive steps from t = 0 through the times `stops`, one record per accepted step.

    Parameters
    ----------
    mass : (n,) ndarray
        Lumped mass (vertex volumes).
    stiffness : (n, n) csr_matrix
        P1 stiffness of the diffusivity.
    u : (n,) ndarray
        Initial field, with the fixed values at the fixed vertices (not modified).
    free : (n,) ndarray of bool
        Vertices without a fixed value.
    reaction : Reaction
    stops : list of float
        Increasing times the steps land on (the last is the end).
    tol : float
        Asked local error per step, as a share of `scale`.
    scale : float
        The size of the field (1 for Fisher-KPP).
    load : (n,) ndarray, optional
        Source per vertex (``int s phi_i`` plus boundary fluxes), per unit time.
    first_step : float, optional
        Length of the first try.
    upper : float, optional
        Upper bound the field is clipped to (1 for Fisher-KPP); 0 is always the lower.
    ndim : int
        The mesh's dimension (chooses the solver, :data:`DIRECT_LIMIT`).

    Yields
    ------
    GrowthStep
    """
    m = np.asarray(mass, dtype=np.float64)
    system = _System(stiffness.tocsr(), free, ndim)
    load = np.zeros_like(m) if load is None else np.where(free, load, 0.0)
    fixed_values = np.asarray(u, dtype=np.float64)[~free].copy()
    u = np.array(u, dtype=np.float64)
    t, end = 0.0, float(stops[-1])
    marks = sorted(set(float(s) for s in stops)
                   | {b for b in reaction.breakpoints() if 0.0 < b < end})
    stop_set = set(float(s) for s in stops)
    dt = float(first_step or end / 100)
    totals = np.zeros(len(BALANCE_TERMS))
    steps = rejected = 0
    while t < end:
        if steps + rejected >= MAX_STEPS:
            raise RuntimeError(f"{MAX_STEPS} steps did not reach t = {end:g}; ask a looser "
                               "error or a shorter duration.")
        target = next(x for x in marks if x > t * (1 + 1e-14) + 1e-300)
        wanted = dt
        h = min(dt, target - t)
        landing = h >= target - t - 1e-12 * max(abs(target), 1.0)
        if landing:
            h = target - t
        try:
            full, terms_full = _one_step(system, m, load, reaction, u, t, h, fixed_values)
            half, terms_a = _one_step(system, m, load, reaction, u, t, 0.5 * h, fixed_values)
            fine, terms_b = _one_step(system, m, load, reaction, half, t + 0.5 * h, 0.5 * h,
                                      fixed_values)
        except ArithmeticError:
            rejected += 1
            dt = 0.25 * h
            continue
        est = float(np.max(np.abs(fine - full), initial=0.0)) / scale
        if est > tol and h > 1e-12 * end:
            rejected += 1
            dt = h * max(0.2, 0.9 * np.sqrt(tol / est))
            continue
        raw = 2.0 * fine - full
        new = np.clip(raw, 0.0, upper if upper is not None else np.inf)
        new[~free] = fixed_values
        terms = 2.0 * (terms_a + terms_b) - terms_full
        terms[-1] = float(np.sum(m * (new - raw)))
        totals += terms
        u = new
        t = target if landing else t + h
        steps += 1
        dt = h * (2.0 if est == 0 else min(2.0, max(0.2, 0.9 * np.sqrt(tol / est))))
        if landing:          # a step cut short to land: its successor may take the full one
            dt = max(dt, wanted)
        yield GrowthStep(t, u, dict(zip(BALANCE_TERMS, totals.tolist())), steps, rejected,
                         landing and target in stop_set)
