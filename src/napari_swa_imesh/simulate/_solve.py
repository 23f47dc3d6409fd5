"""Symmetric positive definite solves: conjugate gradients with algebraic multigrid.

Smoothed aggregation (:mod:`._amg`, from pyamg's parts) is the preconditioner: its cost
grows linearly with the unknowns, which is what lets a 128^3 volume (millions of
unknowns) solve in seconds.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from ._pmultigrid import P2Stiffness, TwoLevelDirichlet
from ._release import release_memory

__all__ = ["DirichletSolver", "SPDSolver", "SolverInfo", "check_constrained",
           "connected_parts", "element_parts", "solve_dirichlet", "solve_spd",
           "split_fixed"]

DEFAULT_TOLERANCE = 1e-10        # relative residual of the conjugate-gradient solve
MAX_ITERATIONS = 2000


@dataclass(frozen=True)
class SolverInfo:
    """What the linear solver did.

    Attributes
    ----------
    unknowns : int
        Size of the system solved (free degrees of freedom).
    iterations : int
        Conjugate-gradient iterations.
    residual : float
        Final relative residual ``|b - A x| / |b|`` of the diagonally scaled system.
    seconds : float
        Set-up plus solve time.
    setup : float
        Of `seconds`, the multigrid set-up (0 when a hierarchy was reused).
    """

    unknowns: int
    iterations: int
    residual: float
    seconds: float
    setup: float = 0.0


def connected_parts(matrix: sparse.csr_matrix) -> np.ndarray:
    """(n,) index of the connected part of each degree of freedom (the matrix pattern)."""
    return csgraph.connected_components(matrix, directed=False)[1]


def element_parts(cells: np.ndarray, n_points: int,
                  edges: np.ndarray | None = None) -> np.ndarray:
    """:func:`connected_parts` of a P1 or P2 stiffness matrix, from its elements.

    Two vertices are connected when an element holds both (an element's matrix couples
    all its degrees of freedom: a group it did not couple to the rest would make that
    group's indicator a zero-energy function); a P2 edge dof lies in its vertices' part.
    The graph is the elements' vertex stars, a tenth of the P2 matrix's entries.

    Parameters
    ----------
    cells : (M, d + 1) ndarray of int
    n_points : int
    edges : (E, 2) ndarray of int, optional
        P2: the vertex pair of each edge dof (numbered after the vertices).

    Returns
    -------
    (n,) ndarray of int
        Part of each dof, ``n = n_points (+ E)``.
    """
    centre = np.repeat(cells[:, :1], cells.shape[1] - 1, axis=1).ravel()
    graph = sparse.csr_matrix((np.ones(centre.size),
                               (centre, cells[:, 1:].ravel())), shape=(n_points, n_points))
    parts = csgraph.connected_components(graph, directed=False)[1]
    return parts if edges is None else np.concatenate([parts, parts[edges[:, 0]]])


def check_constrained(parts: np.ndarray, fixed: np.ndarray, where: str = "",
                      cell_dofs: np.ndarray | None = None,
                      cell_material: np.ndarray | None = None) -> None:
    """Refuse a steady problem with a connected part that touches no fixed value.

    Such a part's potential is undetermined (the system is singular there).

    Parameters
    ----------
    parts : (n,) ndarray of int
        From :func:`connected_parts`.
    fixed : (k,) ndarray of int
        Degrees of freedom with a prescribed value.
    where : str
        Names the condition in the message (e.g. "the x faces").
    cell_dofs, cell_material : ndarray, optional
        Element-to-dof table and the material of each element, to name the materials of
        a floating part in the message.
    """
    anchored = np.zeros(parts.max() + 1, dtype=bool)
    anchored[parts[fixed]] = True
    if anchored.all():
        return
    floating = np.flatnonzero(~anchored[parts])
    what = ""
    if cell_dofs is not None and cell_material is not None:
        hit = np.isin(cell_dofs[:, 0], floating)
        mats = np.unique(cell_material[hit])
        what = f" (material {', '.join(map(str, mats))})"
    raise ValueError(f"{floating.size} nodes{what} are not connected to {where or 'any face'} "
                     "with a fixed value, so their potential is undetermined; include the "
                     "material that separates them or give that region a condition.")


class SPDSolver:
    """Conjugate gradients preconditioned by one AMG hierarchy of `matrix`, reusable.

    Build once, solve many right-hand sides (the time steps of a transient run, the
    axes of the periodic protocol share one matrix). The system is solved symmetrically
    scaled by its diagonal, ``D^-1/2 A D^-1/2``, so the stopping test weighs every row
    alike: with conductivities 1e-6 and 1e6 in one image an unscaled residual is met
    while the low-conductivity part is still wrong.

    Parameters
    ----------
    matrix : (n, n) csr_matrix
        Symmetric positive definite.
    tol : float
        Relative residual of each solve.
    overwrite : bool
        Scale `matrix` in place instead of a copy (for a matrix the caller drops).
    coarse : (n, n_coarse) sparse matrix, optional
        The first coarse space of the multigrid, as its functions' values at the
        unknowns (P2: the P1 functions, :func:`~._assembly.p1_embedding`).
    """

    def __init__(self, matrix: sparse.csr_matrix, *, tol: float = DEFAULT_TOLERANCE,
                 overwrite: bool = False, coarse: sparse.spmatrix | None = None):
        from ._amg import Hierarchy

        t0 = time.perf_counter()
        self.scale = 1.0 / np.sqrt(matrix.diagonal())
        scaled = matrix.tocsr(copy=not overwrite)
        scaled.data *= np.repeat(self.scale, np.diff(scaled.indptr))
        scaled.data *= self.scale[scaled.indices]
        self.matrix = scaled
        self.tol = tol
        # in the scaled unknowns y = D^1/2 x a coarse function is D^1/2 times its values
        self.hierarchy = Hierarchy(scaled, None if coarse is None else
                                   sparse.diags(1.0 / self.scale) @ coarse)
        self.precondition: Callable[[np.ndarray], np.ndarray] = self.hierarchy.precondition
        release_memory()                          # the set-up's products and copies
        self.setup_seconds = time.perf_counter() - t0

    def solve(self, rhs: np.ndarray, x0: np.ndarray | None = None, *,
              overwrite_rhs: bool = False) -> tuple[np.ndarray, SolverInfo]:
        """Solve for one right-hand side, from the initial guess `x0` (default 0);
        `overwrite_rhs` scales `rhs` in place (a vector the caller drops) instead of a copy.

        Raises
        ------
        ValueError
            When the residual does not reach the tolerance (a result that would be wrong
            is not returned).
        """
        from ._amg import matvec, pcg

        t0 = time.perf_counter()
        rhs = np.multiply(rhs, self.scale, out=rhs if overwrite_rhs else None)
        norm_b = float(np.linalg.norm(rhs))
        if norm_b == 0:
            return np.zeros_like(rhs), SolverInfo(rhs.size, 0, 0.0, 0.0)
        y = np.zeros_like(rhs) if x0 is None else x0 / self.scale
        y, iterations = pcg(self.matrix, rhs, self.precondition, y, tol=self.tol,
                            maxiter=MAX_ITERATIONS)
        # the true residual and the unscaled solution in place of new vectors
        check = matvec(self.matrix, y, np.empty_like(rhs))
        residual = float(np.linalg.norm(np.subtract(rhs, check, out=check))) / norm_b
        del check
        x = np.multiply(y, self.scale, out=y)
        release_memory()
        info = SolverInfo(int(rhs.size), iterations, residual, time.perf_counter() - t0)
        if not np.isfinite(residual) or residual > 10 * self.tol:
            raise ValueError(
                f"the linear solver stopped at relative residual {residual:.1e} after "
                f"{info.iterations} iterations (asked {self.tol:.0e}); check that the "
                "conductivities are not extreme (contrast above 1e8) or loosen the "
                "tolerance.")
        return x, info


class _TwoLevelSolver(SPDSolver):
    """:meth:`SPDSolver.solve` on the reduced system of a
    :class:`~._pmultigrid.P2Stiffness` (scaled the same way; its own preconditioner)."""

    def __init__(self, matrix: P2Stiffness, free: np.ndarray, *, tol: float):
        system = TwoLevelDirichlet(matrix, free, tol=tol)
        self.scale, self.matrix, self.tol = system.scale, system.matrix, tol
        self.precondition = system.precondition
        self.system = system
        self.setup_seconds = system.setup_seconds


def solve_spd(matrix: sparse.csr_matrix, rhs: np.ndarray, *, x0: np.ndarray | None = None,
              tol: float = DEFAULT_TOLERANCE, overwrite: bool = False,
              coarse: sparse.spmatrix | None = None) -> tuple[np.ndarray, SolverInfo]:
    """Solve ``matrix @ x = rhs`` for a symmetric positive definite `matrix` (one shot;
    `overwrite` and `coarse` as for :class:`SPDSolver`)."""
    solver = SPDSolver(matrix, tol=tol, overwrite=overwrite, coarse=coarse)
    x, info = solver.solve(rhs, x0)
    return x, SolverInfo(info.unknowns, info.iterations, info.residual,
                         info.seconds + solver.setup_seconds, solver.setup_seconds)


def split_fixed(matrix: sparse.csr_matrix, fixed: np.ndarray
                ) -> tuple[np.ndarray, sparse.csr_matrix, sparse.csr_matrix]:
    """Rows of the free dofs, split by column: ``(free mask, A[free, free], A[free, ~free])``.

    The reduced block stays symmetric positive definite; the coupling block times the
    fixed values moves to the right-hand side.
    """
    free = np.ones(matrix.shape[0], dtype=bool)
    free[fixed] = False
    rows = matrix[free]
    return free, rows[:, free].tocsr(), rows[:, ~free].tocsr()


class DirichletSolver:
    """``matrix @ u = rhs`` with ``u[fixed] = values``, condensed (stays SPD): the split
    and the multigrid hierarchy are made once, then solved for any values, right-hand
    side, initial guess or tolerance (a solve continued to a tighter one reuses them).

    `coarse` (n, n_coarse), optional: the first coarse space of the multigrid (see
    :class:`SPDSolver`), restricted here to the free unknowns and the coarse functions
    that vanish on the fixed ones (columns are coarse dofs numbered as the first
    ``n_coarse`` unknowns, as P1 vertices are among P2 dofs).

    A :class:`~._pmultigrid.P2Stiffness` `matrix` (half storage, its own P1 space) is not
    split: the reduced system is a view of it, solved with the two-level preconditioner
    of :mod:`._pmultigrid` (`coarse` is then not used).
    """

    def __init__(self, matrix: sparse.csr_matrix | P2Stiffness, fixed: np.ndarray, *,
                 tol: float = DEFAULT_TOLERANCE, coarse: sparse.spmatrix | None = None):
        self.n = matrix.shape[0]
        self.fixed = fixed
        if isinstance(matrix, P2Stiffness):
            self.free = np.ones(self.n, dtype=bool)
            self.free[fixed] = False
            self.operator: P2Stiffness | None = matrix
            self.coupling = None
            self.solver: SPDSolver = _TwoLevelSolver(matrix, self.free, tol=tol)
            self._setup = self.solver.setup_seconds
            return
        self.operator = None
        self.free, reduced, self.coupling = split_fixed(matrix, fixed)
        if coarse is not None:
            coarse = coarse.tocsr()[self.free][:, self.free[:coarse.shape[1]]]
        self.solver = SPDSolver(reduced, tol=tol, overwrite=True, coarse=coarse)
        self._setup = self.solver.setup_seconds          # reported with the first solve

    def solve(self, values: np.ndarray, rhs: np.ndarray | None = None, *,
              x0: np.ndarray | None = None, tol: float | None = None
              ) -> tuple[np.ndarray, SolverInfo]:
        """The full vector `u` (fixed entries included); `x0` (full length) is an initial
        guess for the free entries, `tol` overrides the constructor's."""
        u = np.zeros(self.n)
        u[self.fixed] = values
        if self.operator is None:
            b = -(self.coupling @ u[~self.free])
        else:                       # u is zero where free: -(A u)[free], in place
            product = self.operator.matvec(u, np.empty(self.n))
            b = np.compress(self.free, product)
            np.negative(b, out=b)
            del product
        if rhs is not None:
            b += rhs[self.free]
        if tol is not None:
            self.solver.tol = tol
        del u                                   # made again below, not held by the solve
        free, info = self.solver.solve(b, None if x0 is None else x0[self.free],
                                       overwrite_rhs=True)
        del b
        u = np.zeros(self.n)
        u[self.fixed] = values
        u[self.free] = free
        del free
        info = SolverInfo(info.unknowns, info.iterations, info.residual,
                          info.seconds + self._setup, self._setup)
        self._setup = 0.0
        return u, info


def solve_dirichlet(matrix: sparse.csr_matrix, fixed: np.ndarray, values: np.ndarray,
                    rhs: np.ndarray | None = None, *, tol: float = DEFAULT_TOLERANCE,
                    x0: np.ndarray | None = None, coarse: sparse.spmatrix | None = None
                    ) -> tuple[np.ndarray, SolverInfo]:
    """Solve ``matrix @ u = rhs`` with ``u[fixed] = values`` (condensed, stays SPD).

    `x0` (full length) is an initial guess for the free entries; `coarse` as for
    :class:`DirichletSolver`. Returns the full vector `u` (fixed entries included).
    """
    return DirichletSolver(matrix, fixed, tol=tol, coarse=coarse).solve(values, rhs, x0=x0)
