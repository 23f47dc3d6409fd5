"""A sharper lower bound of k_eff in 3-D: the Crouzeix-Raviart flux plus a curl.

The dual principle of :mod:`._dual` bounds ``Q >= Phi(s)^2 / E(s)`` for every flux ``s``
in H(div) with ``div s = 0`` in the mesh and ``s . n = 0`` on the insulated boundary
(``E(s) = int s . C^-1 s``, ``Phi(s)`` its total through the ``max`` face). Its
Crouzeix-Raviart / RT0 flux ``sigma`` is constant per element and stays far below the
truth at high contrast. Here ``s = sigma + curl A`` with ``A`` a continuous piecewise
quadratic vector field (each component in the P2 space of the mesh), zero at every P2
node of the insulated boundary facets, and ``A`` chosen to lower ``E``.

**Why every such A keeps the bound** (the proof; it holds for any A, so the
minimisation need not converge). ``A`` is in H1, so ``curl A`` is in H(div) with
``div curl A = 0``; a continuous field whose every P2 node on a facet is zero vanishes
on that facet, so ``curl A . n``, which involves only A's derivatives along the facet,
is zero there: ``s`` satisfies both conditions whenever ``sigma`` does. The bound is then
``Phi(s)^2 / E(s)`` with ``E(s)`` integrated exactly (degree-two quadrature of the
piecewise-linear ``s``) and ``Phi(s)`` summed over the ``max`` face's facets (exact: s is
linear on each). The flux through the ``min`` face is summed too; the two agree to
round-off (``Phi(curl A)`` is the circulation of ``A`` round the face, where A is zero),
else the curl is dropped and the Crouzeix-Raviart bound kept.

``A`` minimises ``E(sigma + curl A)``: the symmetric positive semi-definite system
``K a = -b`` (``K`` the ``curl . C^-1 curl`` matrix of the P2 vector fields, its kernel
the gradient fields, ``b`` consistent with it) by conjugate gradients with the diagonal
as preconditioner, a fixed number of iterations at most: each iterate lowers ``E`` (CG
minimises the quadratic over a growing Krylov space), so the bound only improves and is a
bound at every iterate.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..mesh import Mesh
from ._assembly import (
    Space,
    _apply,
    _chunks,
    _dot,
    _field_gradients,
    _map,
    _quadrature,
    _shape_coefficients,
    _tensor_rows,
    barycentric_gradients,
)
from ._dual import DualBound, FacetTable
from ._solve import SolverInfo

__all__ = ["CurlBound", "curl_bound", "insulated_nodes"]

#: Most conjugate-gradient iterations of the curl's minimisation (any iterate bounds).
CURL_ITERATIONS = 1000
#: The minimisation stops when its last WINDOW steps lowered the energy by less than
#: SETTLED of it (the bound would move by about as much). Most of the gain comes first:
#: on 14^3 blobs the bound (CR 1.9201) is 2.0356 after 10 steps, 2.0400 after 40 and
#: 2.0416 after 160, while each step costs a product with a matrix three times the
#: primal's size.
WINDOW = 10
SETTLED = 1e-3
#: Largest P2 space (vertices + edges) the curl is added on (besides the memory budget):
#: its assembly and iterations cost several primal solves (10^3 blobs refined once,
#: 55.6k nodes: some 30 s on this loaded machine), so larger meshes keep the CR bound.
CURL_NODES = 100_000
#: Peak bytes per P2 node of the curl's assembly and solve, above the Crouzeix-Raviart
#: solve's peak (measured 8.1 kB at 20^3 blobs, 58.6k nodes; the three-component matrix
#: has about 150 entries per node, built once in 3 x 3 blocks and restricted).
BYTES_PER_CURL_NODE = 9000
#: Elements per chunk of the curl matrix's assembly (900 entries each: 60 MB).
CURL_CHUNK = 8192
#: Relative disagreement of the flux through the two faces above which the curl is
#: dropped (round-off is about 1e-14).
FACE_TOLERANCE = 1e-8

# (v x e_k)_i = eps_ijk v_j
_EPS = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _EPS[_i, _j, _k], _EPS[_i, _k, _j] = 1.0, -1.0


def _curls(space: Space, part: slice, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nq, 30, 3, m) ``curl(phi_a e_k)`` (local dof ``3 a + k``) at the barycentric points
    `lam`, and (m,) volumes."""
    g, vol = barycentric_gradients(space.points, space.cells[part])     # (4, 3, m)
    c = _shape_coefficients(3, 2, lam)                                  # (nq, 10, 4)
    grad = np.einsum("qap,pjm->qajm", c, g)                             # (nq, 10, 3, m)
    curl = np.einsum("ijk,qajm->qakim", _EPS, grad)                     # (nq, 10, 3, 3, m)
    return curl.reshape(len(lam), 30, 3, -1), np.abs(vol)


@dataclass(frozen=True)
class CurlBound:
    """The Crouzeix-Raviart flux corrected by a curl: the lower bound of one solve.

    Attributes
    ----------
    k_lower : float
    potential : (3 * n_p2,) ndarray
        The vector potential ``A`` (P2 node ``i``, component ``k`` at ``3 i + k``).
    base : (M, 3) ndarray
        The Crouzeix-Raviart flux (:attr:`DualBound.flux`).
    scale : float
        ``scale * (base + curl A)`` is the optimally scaled flux.
    space : Space
        The P2 space ``A`` lives on.
    info : SolverInfo
    unknowns : int
    """

    k_lower: float
    potential: np.ndarray
    base: np.ndarray
    scale: float
    space: Space
    info: SolverInfo
    unknowns: int

    def fluxes(self, part: slice, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(nq, 3, m) the scaled flux at the points `lam` of the elements `part`, and
        their volumes."""
        g, vol = barycentric_gradients(self.space.points, self.space.cells[part])  # (4, 3, m)
        c = _shape_coefficients(3, 2, lam)                                 # (nq, 10, 4)
        dofs = 3 * self.space.element_dofs[part][:, :, None] + np.arange(3)
        local = self.potential[dofs]                                       # (m, 10, 3)
        # grad A at the points, (nq, j, k, m) = d_j A_k, then curl_i = eps_ijk d_j A_k
        by_corner = np.einsum("qap,mak->qpkm", c, local)
        grad = np.einsum("pjm,qpkm->qjkm", g, by_corner)
        s = np.stack([grad[:, 1, 2] - grad[:, 2, 1], grad[:, 2, 0] - grad[:, 0, 2],
                      grad[:, 0, 1] - grad[:, 1, 0]], axis=1)
        s += self.base[part].T[None]
        return self.scale * s, np.abs(vol)

    def hypercircle(self, space: Space, values: np.ndarray, tensors: np.ndarray,
                    cell_material: np.ndarray) -> np.ndarray:
        """(M,) ``int_T (s - C grad u) . C^-1 (s - C grad u)`` against the primal potential
        `values` on `space` (P1 or P2): the gap per element (Prager-Synge)."""
        lam, w = _quadrature(3, 2)
        tensors = np.asarray(tensors, dtype=np.float64)
        inverse = np.linalg.inv(tensors)
        out = np.empty(len(space.cells))

        def fill(part: slice) -> None:
            gu = _field_gradients(space, values, part, lam)[0]
            s, vol = self.fluxes(part, lam)
            diff = s - _apply(_tensor_rows(tensors, cell_material[part]), gu)
            density = _dot(diff, _apply(_tensor_rows(inverse, cell_material[part]), diff))
            out[part] = (w @ density) * vol

        for _ in _map(fill, len(space.cells)):
            pass
        return np.maximum(out, 0.0)


def _curl_matrix(space: Space, inverse: np.ndarray, cell_material: np.ndarray
                 ) -> sparse.bsr_matrix:
    """``K[3 i + k, 3 j + l] = int curl(phi_i e_k) . C^-1 curl(phi_j e_l)`` over the P2
    basis ``phi``, as 3 x 3 blocks on the P2 matrix pattern.

    ``curl(phi e_k) = grad phi x e_k = X_k grad phi`` and ``grad phi_a = sum_p c_ap
    grad lambda_p``: an element's block ``(a, b)`` is ``sum_pr Q[a, b, p, r] vol
    grad lambda_p . T_kl grad lambda_r`` with ``T_kl = X_k^T C^-1 X_l`` and ``Q`` the
    quadrature's table (exact, degree two): one small product per element.
    """
    lam, w = _quadrature(3, 2)
    c = _shape_coefficients(3, 2, lam)                                    # (nq, 10, 4)
    table = np.einsum("q,qap,qbr->abpr", w, c, c).reshape(100, 16)
    # T[k, l, j, s] = eps_ijk C^-1_it eps_tsl, per material
    t = np.einsum("ijk,nit,tsl->nkljs", _EPS, inverse, _EPS).reshape(len(inverse), 81)
    n = space.n_dofs
    a, b = np.divmod(np.arange(100), 10)
    keys = (space.element_dofs[:, a].astype(np.int64) * n
            + space.element_dofs[:, b]).T                                 # (100, M)
    pattern, position = np.unique(keys, return_inverse=True)
    position = position.reshape(keys.shape).astype(np.int32)
    del keys
    rows, columns = np.divmod(pattern, n)
    blocks = np.zeros((9, len(pattern)))

    for part in _chunks(len(space.cells), CURL_CHUNK):      # 900 entries per element
        g, vol = barycentric_gradients(space.points, space.cells[part])   # (4, 3, m)
        coefficients = t.T[:, cell_material[part]].reshape(3, 3, 3, 3, -1) * np.abs(vol)
        tg = np.einsum("kljsm,rsm->kljrm", coefficients, g, optimize=True)
        products = np.einsum("pjm,kljrm->klprm", g, tg, optimize=True).reshape(9, 16, -1)
        # einsum, not matmul: BLAS threads stall on a loaded machine (5 s against 1.3 s)
        values = np.einsum("xy,kym->kxm", table, products)               # (9, 100, m)
        del tg, products
        where = position[:, part].ravel()
        for kl in range(9):
            blocks[kl] += np.bincount(where, weights=values[kl].ravel(),
                                      minlength=len(pattern))
    del position
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))])
    square = blocks.T.reshape(-1, 3, 3)
    del blocks
    return sparse.bsr_matrix((square, columns.astype(np.int32), indptr.astype(np.int32)),
                             shape=(3 * n, 3 * n), copy=False)


def _edge_dofs(space: Space, pairs: np.ndarray) -> np.ndarray:
    n = len(space.points)
    assert space.edges is not None
    keys = space.edges[:, 0].astype(np.int64) * n + space.edges[:, 1]
    pairs = np.sort(pairs, axis=1)
    return n + np.searchsorted(keys, pairs[:, 0].astype(np.int64) * n + pairs[:, 1])


def _pcg(matrix: sparse.spmatrix, rhs: np.ndarray, iterations: int, energy: float,
         settled: float, free: np.ndarray | None = None) -> tuple[np.ndarray, int, float]:
    """Diagonal-preconditioned CG for ``matrix x = rhs`` from 0, at most `iterations`
    steps, stopping once the last :data:`WINDOW` steps lowered the complementary energy
    (`energy` at ``x = 0``; each step lowers it by ``alpha r . z``) by less than
    `settled` of it. No error when it stops early: every iterate is usable. With `free`
    (a mask), the system restricted to it (`rhs` zero elsewhere): the preconditioner is
    zero off it, so every search direction, and x, stays there, and the matrix is not
    copied. Returns ``(x, steps, relative residual)``."""
    diagonal = matrix.diagonal()
    if free is not None:
        diagonal = np.where(free, diagonal, 0.0)
    inverse = np.where(diagonal > 0, 1.0 / np.where(diagonal > 0, diagonal, 1.0), 0.0)
    x = np.zeros_like(rhs)
    r = rhs.copy()
    z = inverse * r
    p = z.copy()
    rz = _inner(r, z)
    gains = np.zeros(WINDOW)
    k = 0
    while k < iterations and rz > 0:
        q = matrix @ p
        if free is not None:
            q[~free] = 0.0
        pq = _inner(p, q)
        if not pq > 0:
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        energy -= alpha * rz
        gains[k % WINDOW] = alpha * rz
        z = inverse * r
        rz, old = _inner(r, z), rz
        p = z + (rz / old) * p
        k += 1
        if k >= WINDOW and gains.sum() < settled * energy:
            break
    norm = _inner(rhs, rhs)
    return x, k, float(np.sqrt(_inner(r, r) / norm)) if norm else 0.0


def _inner(u: np.ndarray, v: np.ndarray) -> float:
    """``u . v`` without BLAS (whose threads stall on a loaded machine for vectors of this
    size)."""
    return float(np.einsum("i,i->", u, v))


def _face_flux(space: Space, bound: CurlBound, facets: FacetTable, face: np.ndarray,
               axis: int) -> float:
    """Total of the scaled flux's `axis` component over the facets `face` (planes of
    constant `axis`): the flux in the +axis direction."""
    owner = facets.owners[face, 0]
    corner_of = np.argmax(facets.of_cell[owner] == face[:, None], axis=1)   # opposite
    p = space.points[facets.vertices[face]]                               # (k, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    total = 0.0
    for corner in range(4):        # elements grouped by the corner opposite the facet
        rows = np.flatnonzero(corner_of == corner)
        if not rows.size:
            continue
        point = np.full((1, 4), 1.0 / 3.0)
        point[0, corner] = 0.0
        sub = Space(space.points, space.cells[owner[rows]], 2,
                    space.element_dofs[owner[rows]], space.edges)
        view = CurlBound(bound.k_lower, bound.potential, bound.base[owner[rows]],
                         bound.scale, sub, bound.info, bound.unknowns)
        s = view.fluxes(slice(0, rows.size), point)[0][0]                # (3, k)
        total += float(area[rows] @ s[axis])
    return total


def insulated_nodes(space: Space, facets: FacetTable, axis: int, lo: np.ndarray,
                    hi: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """The boundary facets on the ``min`` and ``max`` planes of `axis` ((F,) masks), and
    the P2 nodes (vertices and edges) of every other boundary facet, where A is zero
    ((n_dofs,) mask)."""
    eps = 1e-9 * float(np.max(hi - lo))
    boundary = facets.boundary
    plane = [boundary & (np.abs(space.points[facets.vertices, axis] - x) <= eps).all(axis=1)
             for x in (lo[axis], hi[axis])]
    tri = facets.vertices[np.flatnonzero(boundary & ~plane[0] & ~plane[1])]
    nodes = np.concatenate([tri.ravel()] + [_edge_dofs(space, tri[:, [i, j]])
                                            for i, j in ((0, 1), (1, 2), (0, 2))])
    zero = np.zeros(space.n_dofs, dtype=bool)
    zero[nodes] = True
    return plane, zero


def curl_bound(mesh: Mesh, space: Space, tensors: np.ndarray, cell_material: np.ndarray,
               axis: int, lo: np.ndarray, hi: np.ndarray, base: DualBound,
               facets: FacetTable, *, iterations: int = CURL_ITERATIONS,
               settled: float = SETTLED) -> CurlBound | None:
    """The Crouzeix-Raviart bound `base` improved by the curl of a P2 vector field.

    Parameters
    ----------
    mesh : Mesh
        A tetrahedral mesh.
    space : Space
        Its P2 space.
    tensors : (n_materials, 3, 3) ndarray
        Conductivities, mesh axis order.
    cell_material : (M,) ndarray of int
    axis : int
        Mesh axis of the flow.
    lo, hi : (3,) ndarray
        The box.
    base : DualBound
        :func:`._dual.dual_bound` along `axis` (its flux is the starting point).
    facets : FacetTable
    iterations : int
        Most conjugate-gradient iterations.
    settled : float
        Relative fall of the energy over :data:`WINDOW` steps below which they stop.

    Returns
    -------
    CurlBound or None
        None when the base bound is zero, the P2 space is above :data:`CURL_NODES` or
        the two faces' fluxes disagree (keep `base`).
    """
    if mesh.ndim != 3 or not base.k_lower > 0 or space.n_dofs > CURL_NODES:
        return None
    n = space.n_dofs
    plane, zero = insulated_nodes(space, facets, axis, lo, hi)
    inverse = np.linalg.inv(np.asarray(tensors, dtype=np.float64))
    lam, w = _quadrature(3, 2)
    rhs = np.zeros(3 * n)
    dofs = (3 * space.element_dofs[:, :, None] + np.arange(3)).reshape(-1, 30)
    sigma = np.ascontiguousarray(base.flux.T)                             # (3, M)
    mean = np.einsum("q,qap->ap", w, _shape_coefficients(3, 2, lam))      # (10, 4)

    def loads(part: slice) -> tuple[slice, np.ndarray]:
        # int_T curl(phi_a e_k) . C^-1 sigma, the curl's mean times the volume
        g, vol = barycentric_gradients(space.points, space.cells[part])
        grad = np.einsum("ap,pjm->ajm", mean, g)                          # (10, 3, m)
        y = _apply(_tensor_rows(inverse, cell_material[part]), sigma[:, part])
        load = np.einsum("ijk,ajm,im->akm", _EPS, grad, y) * np.abs(vol)
        return part, load.reshape(30, -1)

    t0 = time.perf_counter()
    # the matrix does not depend on the axis: made once per mesh (facets.cache)
    key = facets.cache.get("curl key", (None, None, None))
    if key[0] is not space or key[1] is not tensors or key[2] is not cell_material:
        facets.cache["curl key"] = (space, tensors, cell_material)
        whole = _curl_matrix(space, inverse, cell_material).tocsr()
        whole.eliminate_zeros()     # isotropic blocks have exact zeros: a third of them
        facets.cache["curl matrix"] = whole
        del whole
    for part, load in _map(loads, mesh.n_cells):     # summed here, on one thread
        np.add.at(rhs, dofs[part].T, load)
    free = ~np.repeat(zero, 3)
    # E(sigma + curl A) = E(sigma) + 2 (a . rhs + a K a / 2); E(sigma) = its flux
    start = float(base.k_lower * np.prod(np.delete(hi - lo, axis)) / (hi[axis] - lo[axis]))
    potential, k, residual = _pcg(facets.cache["curl matrix"], np.where(free, -rhs, 0.0),
                                  iterations, start / 2, settled, free)
    info = SolverInfo(int(free.sum()), k, residual, time.perf_counter() - t0)
    bound = CurlBound(0.0, potential, base.flux, 1.0, space, info, int(free.sum()))
    energy = 0.0

    def fill(part: slice) -> float:
        s, vol = bound.fluxes(part, lam)
        density = _dot(s, _apply(_tensor_rows(inverse, cell_material[part]), s))
        return float((w @ density) @ vol)

    energy = sum(_map(fill, mesh.n_cells))
    through = [_face_flux(space, bound, facets, np.flatnonzero(f), axis) for f in plane]
    phi = through[1]
    if not energy > 0 or not phi > 0 or abs(through[0] - phi) > FACE_TOLERANCE * phi:
        return None
    length = hi[axis] - lo[axis]
    area = float(np.prod(np.delete(hi - lo, axis)))
    k_lower = phi * phi / energy * length / area
    if not k_lower > base.k_lower:
        return None
    return CurlBound(float(k_lower), potential, base.flux, phi / energy, space, info,
                     int(free.sum()))
