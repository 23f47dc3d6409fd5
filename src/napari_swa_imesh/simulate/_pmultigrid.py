"""P2 without its assembled matrix twice: half storage and a p-multigrid onto P1.

The assembled P2 path kept, at the peak of one mixed solve, the symmetric matrix
(float64), its Dirichlet-reduced copy (float64, scaled), that copy again in float32 for
the Gauss-Seidel smoother, and the Galerkin product ``P^T A P`` onto the P1 space: some
40 bytes per stored entry, 2.4 GB for the matrix alone at 128^3 and a run that did not fit
4 GB. Here the P2 stiffness is held once, as its strict upper triangle and its diagonal
(:class:`P2Stiffness`: ``A x = U x + U^T x + D x``, 12 bytes per upper entry), and

* the Dirichlet reduction is a view: ``A_ff y`` is ``(A [y; 0])_f`` and the fixed values
  move to the right-hand side through ``A [0; u_fixed]`` (no reduced or coupling copy);
* the preconditioner is two-level: a Chebyshev polynomial in the diagonally scaled
  ``A_ff`` smooths (it needs products only, so no second matrix), and the coarse
  correction is the P1 space, whose Galerkin matrix ``P^T A P`` *is* the P1 stiffness
  (P1 functions are P2 functions and the bilinear form is the same), assembled directly on
  the same mesh at a seventh of the unknowns and solved by one V-cycle of the
  smoothed-aggregation hierarchy of :mod:`._amg`.

The result is the same discrete solution as the assembled path to the solver's tolerance
(the operator is the same matrix; only the preconditioner differs, and the conjugate
gradients are checked in float64 against the true residual); the tests hold the two
equal on small meshes.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import sparse
from scipy.linalg import eigvalsh_tridiagonal

from ._assembly import Space, p1_embedding, stiffness_matrix, stiffness_upper
from ._release import release_memory
from ._sparse import matvec_into, symmetric_from_upper

__all__ = ["P2Stiffness", "TwoLevelDirichlet", "coarse_space", "p2_stiffness",
           "stiffness_operator"]

# Smoothing: degree 1 (a damped Jacobi step, 1 / 0.5625 lambda_max) took as many
# iterations as degrees 2-4 on the 32^3 blobs (20 against 19) at half the products, and
# less time than the assembled path's Gauss-Seidel (1.0 s against 1.1 s of CPU)
CHEBYSHEV_DEGREE = 1      # the smoothing polynomial's degree (its products of A, plus 1)
CHEBYSHEV_RATIO = 8.0     # the smoothed part of the spectrum: [lambda_max / ratio, lambda_max]
LANCZOS_STEPS = 10        # for lambda_max of the scaled A_ff, a lower estimate (3.9 % low
LANCZOS_MARGIN = 1.1      # at 10 steps on the 32^3 blobs) raised by this margin: a range
                          # below lambda_max would amplify the top modes


class P2Stiffness:
    """A symmetric stiffness matrix held as its strict upper triangle and diagonal, with
    the P1 space the multigrid coarsens onto.

    Parameters
    ----------
    upper : (n, n) csr_matrix
        Canonical, entries above the diagonal only.
    diagonal : (n,) ndarray
    embedding : (n, N) csr_matrix
        The P1 functions among the P2 ones (:func:`~._assembly.p1_embedding`).
    p1 : (N, N) csr_matrix
        The P1 stiffness on the same mesh, ``embedding^T A embedding``.
    """

    def __init__(self, upper: sparse.csr_matrix, diagonal: np.ndarray,
                 embedding: sparse.csr_matrix, p1: sparse.csr_matrix):
        self.upper = upper
        self._lower = upper.T                 # a CSC view: ``U^T x`` without a copy
        self._diagonal = diagonal
        self.embedding = embedding
        self.p1 = p1
        self.shape = upper.shape
        self.dtype = np.dtype(np.float64)
        self._work: np.ndarray | None = None      # :meth:`matvec`'s one temporary

    @property
    def nnz(self) -> int:
        """Entries of the symmetric matrix it stands for (both triangles, the diagonal)."""
        return 2 * int(self.upper.nnz) + self.shape[0]

    @property
    def nbytes(self) -> int:
        """Bytes held: the upper triangle, the diagonal, the P1 space and its matrix."""
        parts = (self.upper, self.embedding, self.p1)
        return int(self._diagonal.nbytes + sum(m.data.nbytes + m.indices.nbytes
                                               + m.indptr.nbytes for m in parts))

    def diagonal(self) -> np.ndarray:
        """(n,) a copy of the diagonal."""
        return self._diagonal.copy()

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        y = self.upper @ x
        y += self._lower @ x
        y += (self._diagonal if x.ndim == 1 else self._diagonal[:, None]) * x
        return y

    def matvec(self, x: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``self @ x`` for a vector, written into `out` (returned): the same products
        and sums as ``@`` (scipy's kernels into zeroed vectors), bit for bit, with one
        temporary kept between calls instead of three new full-length vectors a call."""
        if self._work is None:
            self._work = np.empty(self.shape[0])
        work = self._work
        matvec_into(self.upper, x, out)
        out += matvec_into(self._lower, x, work)
        out += np.multiply(self._diagonal, x, out=work)
        return out

    def tocsr(self) -> sparse.csr_matrix:
        """The symmetric CSR matrix (for a caller that needs rows: the periodic protocol)."""
        return symmetric_from_upper(self.upper, self._diagonal)


def p2_stiffness(space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                 volumes: np.ndarray | None = None) -> P2Stiffness:
    """The P2 stiffness of `space` as a :class:`P2Stiffness` (arguments as for
    :func:`~._assembly.stiffness_matrix`).

    Returns
    -------
    P2Stiffness
        The same matrix as :func:`~._assembly.stiffness_matrix` (both come from one
        upper triangle), with the P1 stiffness of the mesh beside it.
    """
    if space.order != 2:
        raise ValueError(f"p2_stiffness takes a P2 space, not P{space.order}.")
    upper, diagonal = stiffness_upper(space, tensors, cell_material, volumes)
    p1 = stiffness_matrix(fe_space_of(space), tensors, cell_material)
    release_memory()
    return P2Stiffness(upper, diagonal, p1_embedding(space), p1)


def stiffness_operator(space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                       volumes: np.ndarray | None = None, *, periodic: bool = False
                       ) -> P2Stiffness | sparse.csr_matrix:
    """The stiffness a steady solve takes: P2 of the mixed protocol in half storage
    (:func:`p2_stiffness`), else (P1, or the periodic protocol, which reduces the matrix's
    rows) the assembled CSR matrix of :func:`~._assembly.stiffness_matrix`.

    Returns
    -------
    P2Stiffness or (n, n) csr_matrix
    """
    if space.order == 2 and not periodic:
        return p2_stiffness(space, tensors, cell_material, volumes)
    return stiffness_matrix(space, tensors, cell_material, volumes)


def coarse_space(matrix: P2Stiffness | sparse.csr_matrix, space: Space
                 ) -> sparse.csr_matrix | None:
    """The P1 functions among the dofs of `space` (:func:`~._assembly.p1_embedding`), the
    one a :class:`P2Stiffness` `matrix` already holds rather than a second copy (P2 at
    128^3: some 200 MB)."""
    if isinstance(matrix, P2Stiffness):
        return matrix.embedding
    return p1_embedding(space)


def fe_space_of(space: Space) -> Space:
    """The P1 space on the mesh of `space`."""
    return Space(space.points, space.cells, 1, space.cells)


def _dot(u: np.ndarray, v: np.ndarray) -> float:
    return float(np.einsum("i,i->", u, v))      # einsum's own loop, not a BLAS thread


def _largest_eigenvalue(apply, n: int) -> float:
    """Lanczos estimate of the largest eigenvalue of a symmetric operator (from below;
    the caller adds a margin). Seeded: the same operator gives the same estimate.

    `apply(x, out)` writes the product into `out`; the four vectors are made once and
    the steps done in place (the values of new vectors per step, bit for bit).
    """
    v = np.random.default_rng(0).standard_normal(n)
    v /= np.sqrt(_dot(v, v))
    previous = np.zeros(n)
    w, scratch = np.empty(n), np.empty(n)
    alphas, betas = [], []
    beta = 0.0
    for _ in range(min(LANCZOS_STEPS, n)):
        w = apply(v, w)
        w -= np.multiply(beta, previous, out=scratch)     # A v - beta * previous
        alpha = _dot(w, v)
        w -= np.multiply(alpha, v, out=scratch)
        alphas.append(alpha)
        beta = np.sqrt(_dot(w, w))
        if beta <= 1e-12 * abs(alpha):
            break
        betas.append(beta)
        # previous, v = v, w / beta, in the buffer the old previous leaves free
        following = np.divide(w, beta, out=previous)
        previous, v = v, following
    return float(eigvalsh_tridiagonal(np.array(alphas), np.array(betas[:len(alphas) - 1]),
                                      ).max())


class _Scaled:
    """``S A_ff S`` on the free unknowns, S = D_ff^-1/2, applied through the full operator."""

    def __init__(self, operator: P2Stiffness, free: np.ndarray, scale: np.ndarray):
        self.operator, self.free, self.scale = operator, free, scale
        self.shape = (int(free.sum()),) * 2
        self._full = np.zeros(operator.shape[0])
        self._product = np.empty(operator.shape[0])

    def __matmul__(self, y: np.ndarray) -> np.ndarray:
        return self.matvec(y, np.empty(self.shape[0]))

    def matvec(self, y: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``self @ y`` into `out` (not `y`), through two kept full-length vectors."""
        self._full[self.free] = np.multiply(self.scale, y, out=out)
        product = self.operator.matvec(self._full, self._product)
        np.compress(self.free, product, out=out)
        return np.multiply(self.scale, out, out=out)


class TwoLevelDirichlet:
    """The preconditioned reduced system of a :class:`P2Stiffness` with fixed dofs.

    Solves in the scaled free unknowns ``y = D_ff^1/2 u_f`` (unit diagonal, as
    :class:`~._solve.SPDSolver` does) with conjugate gradients preconditioned by a
    Chebyshev smoother and a coarse correction in the P1 functions that vanish on the
    fixed dofs (their Galerkin matrix is the P1 stiffness on the free vertices, whose
    multigrid hierarchy is built here once).

    Parameters
    ----------
    operator : P2Stiffness
    free : (n,) ndarray of bool
        The unknowns (not fixed).
    tol : float
        Relative residual of each solve (read from the attribute, may be changed).
    """

    def __init__(self, operator: P2Stiffness, free: np.ndarray, *, tol: float):
        from ._amg import Hierarchy

        t0 = time.perf_counter()
        self.tol = tol
        self.scale = 1.0 / np.sqrt(operator.diagonal()[free])
        self.matrix = _Scaled(operator, free, self.scale)
        n_vertices = operator.p1.shape[0]
        free_vertices = free[:n_vertices]
        p1 = operator.p1[free_vertices][:, free_vertices]
        coarse_scale = 1.0 / np.sqrt(p1.diagonal())
        p1 = sparse.diags(coarse_scale) @ p1 @ sparse.diags(coarse_scale)
        self.hierarchy = Hierarchy(p1.tocsr())
        del p1                              # kept by the hierarchy in float32
        # the coarse functions in the scaled unknowns, each scaled to the coarse unit
        # diagonal: Q = D_ff^1/2 P_ff E (its Galerkin matrix is the scaled P1 matrix)
        q = operator.embedding[free][:, free_vertices]
        q = (sparse.diags(1.0 / self.scale) @ q @ sparse.diags(coarse_scale)).tocsr()
        self.prolongator = q.astype(np.float32)
        del q                               # not through the eigenvalue's products
        self.restrictor = self.prolongator.T.tocsr()
        top = LANCZOS_MARGIN * _largest_eigenvalue(self.matrix.matvec,
                                                   self.matrix.shape[0])
        self.interval = (top / CHEBYSHEV_RATIO, top)
        # the cycle's vectors, made once: the result (overwritten by the next cycle), a
        # residual and its float32 copy for the coarse level
        n_free = self.matrix.shape[0]
        self._z, self._work = np.empty(n_free), np.empty(n_free)
        self._single = np.empty(n_free, dtype=np.float32)
        release_memory()                          # the set-up's products and copies
        self.setup_seconds = time.perf_counter() - t0

    def _smooth(self, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Chebyshev polynomial of degree `CHEBYSHEV_DEGREE` in the scaled A times `b`
        (the iteration from zero for ``A x = b`` on the smoothed interval): symmetric.
        Written into `out` when given (which may be `b`)."""
        low, high = self.interval
        theta, delta = 0.5 * (high + low), 0.5 * (high - low)
        sigma = theta / delta
        rho = 1.0 / sigma
        if CHEBYSHEV_DEGREE > 1:
            step = b / theta
            r = b.copy()
        x = np.divide(b, theta, out=out)          # the first step, b / theta
        for _ in range(CHEBYSHEV_DEGREE - 1):
            r -= self.matrix @ step
            rho_next = 1.0 / (2.0 * sigma - rho)
            step *= rho_next * rho
            step += (2.0 * rho_next / delta) * r
            x += step
            rho = rho_next
        return x

    def precondition(self, r: np.ndarray) -> np.ndarray:
        """One two-level cycle for ``A z = r`` from zero: smooth, P1 correction, smooth.

        The result is a vector of the cycle's own that the next call overwrites (the
        conjugate gradients use it before they ask again); the steps are those of new
        vectors per call, in place, so the same values bit for bit.
        """
        work, single = self._work, self._single
        x = self._smooth(r, self._z)
        residual = np.subtract(r, self.matrix.matvec(x, work), out=work)
        single[...] = residual                                 # astype(float32)
        coarse = self.hierarchy.precondition(self.restrictor @ single)
        x += matvec_into(self.prolongator, coarse.astype(np.float32), single)
        residual = np.subtract(r, self.matrix.matvec(x, work), out=work)
        x += self._smooth(residual, residual)
        return x
