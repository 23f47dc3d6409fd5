"""Smoothed-aggregation multigrid and conjugate gradients, built from pyamg's parts.

pyamg's own driver (``smoothed_aggregation_solver``) keeps the coarse levels in BSR
format, where scipy sums duplicate entries in a Python loop (seconds per level at a
million unknowns) and every relaxation sweep is slower than on CSR. Here every level is
CSR; the set-up is the same method (symmetric strength with theta 0, standard
aggregation, prolongator smoothed by Jacobi with row-local weights, the constant vector
improved by Gauss-Seidel), and the V-cycle and the conjugate gradients are ours: no
residual is computed inside each preconditioner application, dot products do not go
through a threaded BLAS (on a busy two-core machine the thread hand-off cost more than
the product), and the hierarchy is kept in float32 (the preconditioner only has to be
close to the inverse; the iteration itself runs in float64 and is checked in float64).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import sparse

from ._sparse import matvec_into

__all__ = ["Hierarchy", "matvec", "pcg"]

MAX_COARSE = 500           # unknowns solved directly at the bottom of the V-cycle
MAX_DENSE = 2000           # above this a stalled bottom level is factorised sparsely
IMPROVE_SWEEPS = 4         # symmetric Gauss-Seidel sweeps on the near-null vector
PRECONDITIONER_DTYPE = np.float32
RECOMPUTE = 8              # conjugate-gradient steps between true residuals
SWEEP = "symmetric"        # Gauss-Seidel before and after the coarse correction


class Hierarchy:
    """A smoothed-aggregation V-cycle for a symmetric positive definite CSR matrix.

    Parameters
    ----------
    matrix : (n, n) csr_matrix
        Symmetric positive definite, scaled to a unit diagonal for the best smoothing.
    prolongator : (n, n_coarse) sparse matrix, optional
        A first coarse level given by the caller (P2: the P1 functions, whose Galerkin
        matrix is the P1 stiffness); aggregation takes over below it.
    """

    def __init__(self, matrix: sparse.csr_matrix,
                 prolongator: sparse.csr_matrix | None = None):
        from pyamg.aggregation import (
            fit_candidates,
            jacobi_prolongation_smoother,
            standard_aggregation,
        )
        from pyamg.relaxation.relaxation import gauss_seidel
        from pyamg.strength import symmetric_strength_of_connection

        a = matrix.tocsr()
        self.matrices: list[sparse.csr_matrix] = []
        self.prolongators: list[sparse.csr_matrix] = []
        self.restrictors: list[sparse.csr_matrix] = []
        if prolongator is not None and a.shape[0] > MAX_COARSE:
            a = self._add_level(a, prolongator.tocsr())
        near_null = np.ones((a.shape[0], 1))
        zero = np.zeros((a.shape[0], 1))
        for _ in range(IMPROVE_SWEEPS):
            gauss_seidel(a, near_null, zero, sweep="forward")
            gauss_seidel(a, near_null, zero, sweep="backward")
        while a.shape[0] > MAX_COARSE:
            strength = symmetric_strength_of_connection(a, theta=0.0)
            aggregates = standard_aggregation(strength)[0]
            if not 0 < aggregates.shape[1] < a.shape[0]:   # nothing left to coarsen
                break
            tentative, near_null = fit_candidates(aggregates, near_null)
            p = jacobi_prolongation_smoother(a, tentative.tocsr(), strength, near_null,
                                             weighting="local").tocsr()
            del strength, aggregates, tentative
            a = self._add_level(a, p)
        self.coarse_solve = _coarse_solver(a)
        self.sizes = [m.shape[0] for m in self.matrices] + [a.shape[0]]

    def _add_level(self, a: sparse.csr_matrix, p: sparse.csr_matrix) -> sparse.csr_matrix:
        """Keep `a` and its transfers (in the preconditioner's precision); return the
        Galerkin coarse matrix ``P^T A P``."""
        r = p.T.tocsr()
        coarse = (r @ (a @ p)).tocsr()
        self.matrices.append(_single(a))
        self.prolongators.append(_single(p))
        self.restrictors.append(_single(r))
        return coarse

    def precondition(self, residual: np.ndarray) -> np.ndarray:
        """One V-cycle for ``A z = residual`` from ``z = 0`` (symmetric: forward
        Gauss-Seidel down, backward up)."""
        return self._cycle(0, residual.astype(PRECONDITIONER_DTYPE)).astype(np.float64)

    def _cycle(self, level: int, b: np.ndarray) -> np.ndarray:
        from pyamg.relaxation.relaxation import gauss_seidel

        if level == len(self.matrices):
            return self.coarse_solve(b)
        a = self.matrices[level]
        x = np.zeros_like(b)
        gauss_seidel(a, x, b, sweep=SWEEP)
        x += self.prolongators[level] @ self._cycle(level + 1,
                                                    self.restrictors[level] @ (b - a @ x))
        gauss_seidel(a, x, b, sweep=SWEEP)
        return x


def _coarse_solver(a: sparse.csr_matrix):
    """The bottom of the V-cycle: a dense pseudo-inverse when small, else (aggregation
    stalled, e.g. on unconnected unknowns) a sparse LU, never a huge dense matrix."""
    if a.shape[0] <= MAX_DENSE:
        dense = a.toarray()
        inverse = np.linalg.pinv(0.5 * (dense + dense.T)).astype(PRECONDITIONER_DTYPE)
        return lambda b: inverse @ b
    from scipy.sparse.linalg import splu

    lu = splu(a.astype(np.float64).tocsc())
    return lambda b: lu.solve(b.astype(np.float64)).astype(b.dtype)


def _single(m: sparse.csr_matrix) -> sparse.csr_matrix:
    m = m.astype(PRECONDITIONER_DTYPE)
    m.sort_indices()
    return m


def _dot(u: np.ndarray, v: np.ndarray) -> float:
    return float(np.einsum("i,i->", u, v))      # einsum's own loop, not a BLAS thread


def matvec(matrix, x: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``matrix @ x`` written into `out` (float64, len rows) and returned: an operator
    with its own ``matvec`` (:mod:`._pmultigrid`) uses it, a CSR matrix scipy's own kernel
    into the zeroed `out` (what ``@`` does into a new vector: the same sums, bit for bit),
    anything else ``@`` copied in."""
    own = getattr(matrix, "matvec", None)
    if own is not None:
        return own(x, out)
    if (sparse.issparse(matrix) and matrix.format == "csr" and x.ndim == 1
            and matrix.dtype == np.float64 and x.dtype == np.float64):
        return matvec_into(matrix, x, out)
    out[...] = matrix @ x
    return out


def pcg(matrix: sparse.csr_matrix, rhs: np.ndarray,
        precondition: Callable[[np.ndarray], np.ndarray], x: np.ndarray, *, tol: float,
        maxiter: int) -> tuple[np.ndarray, int]:
    """Preconditioned conjugate gradients until ``|rhs - A x| <= tol |rhs|``.

    `x` (the initial guess) is updated in place and returned with the iteration count.
    Stops early, unconverged, if the search direction degenerates (the caller checks the
    residual). The vectors are made once and updated in place (``out=``): the same
    operations in the same order as with new vectors per step, so the same iterates bit
    for bit, without a few full-length temporaries per step at the peak of a P2 solve.
    `precondition` may return a buffer of its own that its next call overwrites.
    """
    norm_b = np.sqrt(_dot(rhs, rhs))
    q = np.empty_like(rhs)
    r = np.subtract(rhs, matvec(matrix, x, q))
    goal = tol * norm_b
    if np.sqrt(_dot(r, r)) <= goal:
        return x, 0
    z = precondition(r)
    p = z.copy()
    r_old = np.empty_like(r)
    step = np.empty_like(r)
    rz = _dot(r, z)
    for it in range(1, maxiter + 1):
        matvec(matrix, p, q)
        curvature = _dot(p, q)
        if not curvature > 0:
            return x, it
        alpha = rz / curvature
        x += np.multiply(alpha, p, out=step)
        np.copyto(r_old, r)
        if it % RECOMPUTE == 0:          # the updated residual drifts from the true one
            np.subtract(rhs, matvec(matrix, x, q), out=r)
        else:
            r -= np.multiply(alpha, q, out=step)
        if np.sqrt(_dot(r, r)) <= goal:
            return x, it
        z = precondition(r)
        rz_new = _dot(r, z)
        # Polak-Ribiere (flexible CG): tolerant of a preconditioner that is not exactly
        # linear, as a float32 V-cycle is not
        p *= (rz_new - _dot(r_old, z)) / rz
        p += z
        rz = rz_new
    return x, maxiter
