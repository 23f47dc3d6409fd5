"""Our own P1/P2 Lagrange assembly on simplices: stiffness, energy, element fluxes.

scikit-fem is the reference (the tests require our stiffness to equal its matrix to
1e-12, with its numbering of the degrees of freedom); this module exists for the sizes a
128^3 image gives, ten million tetrahedra: scikit-fem keeps every element's basis
gradients and a 16-entries-per-element COO list (the whole command peaked at 9.8 GB
there), whereas here elements are taken in chunks and only the upper-triangle pair values
reach a compressed matrix.

With affine simplices and a conductivity constant per element, every gradient of a P1 or
P2 basis function is ``grad phi_a = sum_p c_ap(lambda) grad lambda_p`` (``c`` constant for
P1, linear in the barycentric coordinates for P2), so the element matrix is
``vol * sum_pq Q[a, b, p, q] (grad lambda_p . C grad lambda_q)`` with ``Q`` a table
computed once from an exact quadrature of degree two.
"""

from __future__ import annotations

import os
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..mesh import Mesh
from ._release import release_memory
from ._sparse import PairwiseSum, symmetric_from_upper

__all__ = ["Space", "assemble_pairs", "assemble_upper", "barycentric_gradients",
           "cell_fluxes", "cell_gradients", "cell_volumes", "dissipation", "fe_space",
           "p1_embedding", "stiffness_matrix", "stiffness_upper"]

CHUNK = 1 << 16          # elements per chunk of arithmetic: temporaries of a few MB
BATCH = 1 << 23          # entries per sparse conversion: lists of some 100 MB
WORKERS = min(2, os.cpu_count() or 1)   # numpy releases the GIL in these array loops

# local edges in scikit-fem's reference order (the P2 dofs 3.. or 4.. follow it)
_EDGES = {2: ((0, 1), (1, 2), (0, 2)),
          3: ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))}


@dataclass(frozen=True)
class Space:
    """The P1 or P2 degrees of freedom of a simplex mesh, numbered as scikit-fem does.

    Vertices first (``0 .. N-1``, the mesh's order), then for P2 one per edge, edges
    sorted by their (smaller, larger) vertex pair.

    Attributes
    ----------
    points : (N, d) ndarray
    cells : (M, d + 1) ndarray of int
    order : int
    element_dofs : (M, n_local) ndarray of int
        Vertices, then (P2) the edges in the reference order ``_EDGES[d]``.
    edges : (E, 2) ndarray of int or None
        P2: the vertex pair of each edge dof.
    """

    points: np.ndarray
    cells: np.ndarray
    order: int
    element_dofs: np.ndarray
    edges: np.ndarray | None = None

    @property
    def ndim(self) -> int:
        return int(self.points.shape[1])

    @property
    def n_dofs(self) -> int:
        return len(self.points) + (0 if self.edges is None else len(self.edges))

    @property
    def doflocs(self) -> np.ndarray:
        """(d, n) coordinates of the dofs: vertices, then (P2) edge midpoints."""
        if self.edges is None:
            return self.points.T
        mid = 0.5 * (self.points[self.edges[:, 0]] + self.points[self.edges[:, 1]])
        return np.concatenate([self.points, mid]).T


def fe_space(mesh: Mesh, order: int = 1) -> Space:
    """The :class:`Space` of P1 (``order=1``) or P2 elements on `mesh`."""
    points = np.ascontiguousarray(mesh.points, dtype=np.float64)
    cells = mesh.cells
    if order == 1:
        return Space(points, cells, 1, cells)
    n = len(points)
    pairs = np.array(_EDGES[mesh.ndim]).T
    lo = np.minimum(cells[:, pairs[0]], cells[:, pairs[1]]).astype(np.int64)
    hi = np.maximum(cells[:, pairs[0]], cells[:, pairs[1]]).astype(np.int64)
    keys, inverse = np.unique(lo * n + hi, return_inverse=True)
    del lo, hi
    # int32 tables while every dof times 4 (room for the curl's 3 per node) fits: half the
    # bytes of the largest arrays a P2 solve holds besides its matrix (~250 MB at 128^3)
    index = np.int32 if 4 * (n + len(keys)) < 2 ** 31 else np.int64
    edges = np.stack([keys // n, keys % n], axis=1).astype(index)
    del keys
    k = cells.shape[1]
    element_dofs = np.empty((len(cells), k + pairs.shape[1]), dtype=index)
    element_dofs[:, :k] = cells
    element_dofs[:, k:] = inverse.reshape(len(cells), pairs.shape[1])
    element_dofs[:, k:] += n
    return Space(points, cells, 2, element_dofs, edges)


def _quadrature(d: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric points (nq, d + 1) and weights (sum 1) exact for degree 2 (P2:
    the product of two gradients) or 0 (P1: a constant)."""
    if order == 1:
        return np.full((1, d + 1), 1.0 / (d + 1)), np.ones(1)
    if d == 2:
        lam = np.array([[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]])
        return lam, np.full(3, 1.0 / 3.0)
    a, b = 0.5854101966249685, 0.1381966011250105
    lam = np.full((4, 4), b)
    np.fill_diagonal(lam, a)
    return lam, np.full(4, 0.25)


def _shape_coefficients(d: int, order: int, lam: np.ndarray) -> np.ndarray:
    """(nq, n_local, d + 1) ``c`` with ``grad phi_a = sum_p c[q, a, p] grad lambda_p``."""
    nq = lam.shape[0]
    if order == 1:
        return np.broadcast_to(np.eye(d + 1), (nq, d + 1, d + 1)).copy()
    edges = _EDGES[d]
    c = np.zeros((nq, d + 1 + len(edges), d + 1))
    for i in range(d + 1):                       # lambda_i (2 lambda_i - 1)
        c[:, i, i] = 4.0 * lam[:, i] - 1.0
    for k, (i, j) in enumerate(edges):           # 4 lambda_i lambda_j
        c[:, d + 1 + k, i] = 4.0 * lam[:, j]
        c[:, d + 1 + k, j] = 4.0 * lam[:, i]
    return c


def _pair_table(d: int, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local pairs ``a <= b`` and the (K, P) table from the products ``G_pq`` of the
    barycentric gradients, pairs ``p <= q`` (off-diagonal ones counted twice), to their
    entries."""
    lam, w = _quadrature(d, order)
    c = _shape_coefficients(d, order, lam)
    a, b = np.triu_indices(c.shape[1])
    q = np.einsum("x,xkp,xkr->kpr", w, c[:, a], c[:, b])       # (K, d+1, d+1)
    p, r = np.triu_indices(d + 1)
    table = q[:, p, r] + np.where(p != r, q[:, r, p], 0.0)
    return a, b, table


def barycentric_gradients(points: np.ndarray, cells: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the barycentric coordinates, (d + 1, d, m), and signed volumes, (m,).

    Component-major: every operation below runs on contiguous rows of m numbers, several
    times faster than on (m, 4, 3) blocks; ``np.take`` gathers the vertices (a third of
    the time of fancy indexing on cells that jump around the point list).
    """
    x = np.take(points, cells, axis=0).transpose(2, 1, 0)        # (d, d + 1, m) view
    e = x[:, 1:] - x[:, :1]                                       # (component, edge, m)
    d, m = e.shape[0], e.shape[2]
    g = np.empty((d + 1, d, m))
    if d == 3:                 # rows of the inverse Jacobian: cross products of edges
        for k in range(3):
            u, v = e[:, (k + 1) % 3], e[:, (k + 2) % 3]
            out = g[k + 1]
            np.multiply(u[1], v[2], out=out[0])
            out[0] -= u[2] * v[1]
            np.multiply(u[2], v[0], out=out[1])
            out[1] -= u[0] * v[2]
            np.multiply(u[0], v[1], out=out[2])
            out[2] -= u[1] * v[0]
        det = e[0, 0] * g[1, 0] + e[1, 0] * g[1, 1] + e[2, 0] * g[1, 2]
    else:
        g[1, 0], g[1, 1] = e[1, 1], -e[0, 1]
        g[2, 0], g[2, 1] = -e[1, 0], e[0, 0]
        det = e[0, 0] * e[1, 1] - e[1, 0] * e[0, 1]
    g[1:] *= 1.0 / det
    np.add(g[1], g[2], out=g[0])
    for k in range(3, d + 1):
        g[0] += g[k]
    np.negative(g[0], out=g[0])
    return g, det / (6.0 if d == 3 else 2.0)


def _chunks(m: int, size: int = CHUNK, start: int = 0):
    for first in range(start, start + m, size):
        yield slice(first, min(first + size, start + m))


def _map(fn, m: int, start: int = 0):
    """``fn(chunk)`` over the chunks of elements ``start .. start + m``, results in order.

    Chunks run on `WORKERS` threads, at most two per thread ahead of the consumer, so
    memory stays that of a few chunks and every sum is taken in the same order as on
    one thread (the results do not depend on the scheduling).
    """
    parts = _chunks(m, CHUNK, start)
    if WORKERS < 2 or m <= CHUNK:
        yield from map(fn, parts)
        return
    with ThreadPoolExecutor(WORKERS) as pool:
        pending: deque = deque()
        for part in parts:
            pending.append(pool.submit(fn, part))
            if len(pending) > 2 * WORKERS:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _apply(tensor_rows: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``C v`` for (d * d, m) tensor rows and (..., d, m) vectors, row by row."""
    d = vectors.shape[-2]
    out = np.empty_like(vectors)
    for i in range(d):
        np.multiply(tensor_rows[i * d], vectors[..., 0, :], out=out[..., i, :])
        for j in range(1, d):
            out[..., i, :] += tensor_rows[i * d + j] * vectors[..., j, :]
    return out


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Component sum of (..., d, m) vectors: (..., m)."""
    out = u[..., 0, :] * v[..., 0, :]
    for i in range(1, u.shape[-2]):
        out += u[..., i, :] * v[..., i, :]
    return out


def _tensor_rows(tensors: np.ndarray, cell_material: np.ndarray) -> np.ndarray:
    """(d * d, m) the conductivity of each element, one component per row."""
    return tensors.reshape(len(tensors), -1).T[:, cell_material]


def _gradient_products(space: Space, part: slice, tensors: np.ndarray,
                       cell_material: np.ndarray, volumes: np.ndarray | None = None
                       ) -> np.ndarray:
    """(P, m) ``vol * grad lambda_p . C grad lambda_q`` for the pairs ``p <= q``; the
    signed volumes go to ``volumes[part]`` if given."""
    g, vol = barycentric_gradients(space.points, space.cells[part])
    if volumes is not None:
        volumes[part] = vol
    c = _tensor_rows(tensors, cell_material[part])
    c *= np.abs(vol)
    cg = _apply(c, g)                                                  # C grad lambda
    p, q = np.triu_indices(g.shape[0])
    out = np.empty((len(p), g.shape[2]))
    for k, (i, j) in enumerate(zip(p, q)):
        out[k] = _dot(g[i], cg[j])
    return out


def stiffness_matrix(space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                     volumes: np.ndarray | None = None) -> sparse.csr_matrix:
    """Assemble ``K[i, j] = sum_e int_e (C_e grad phi_j) . grad phi_i`` (CSR, symmetric).

    Parameters
    ----------
    space : Space
    tensors : (n_materials, d, d) ndarray
        Conductivity tensors in the mesh's axis order.
    cell_material : (M,) ndarray of int
        Row of `tensors` for each element.
    volumes : (M,) ndarray, optional
        Filled with the signed element volumes on the way (saves
        :func:`cell_volumes` its pass over the elements).
    """
    return symmetric_from_upper(*stiffness_upper(space, tensors, cell_material, volumes))


def stiffness_upper(space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                    volumes: np.ndarray | None = None
                    ) -> tuple[sparse.csr_matrix, np.ndarray]:
    """:func:`stiffness_matrix` as its strict upper triangle and its diagonal.

    Half the memory of the symmetric matrix, and what it is made from (no mirror is
    laid out); arguments as for :func:`stiffness_matrix`.

    Returns
    -------
    upper : (n, n) csr_matrix
        Canonical, entries above the diagonal only.
    diagonal : (n,) ndarray
    """
    a, b, table = _pair_table(space.ndim, space.order)
    tensors = np.asarray(tensors, dtype=np.float64)
    p1 = space.order == 1                       # the table is the identity: skip it

    def values(part: slice) -> np.ndarray:
        products = _gradient_products(space, part, tensors, cell_material, volumes)
        return products if p1 else table @ products

    return assemble_upper(space.element_dofs, space.n_dofs, a, b, values)


def assemble_pairs(element_dofs: np.ndarray, n: int, a: np.ndarray, b: np.ndarray,
                   values) -> sparse.csr_matrix:
    """A symmetric CSR matrix from element values of the local pairs ``a <= b``
    (:func:`assemble_upper`, then the mirror and the diagonal placed around each row)."""
    return symmetric_from_upper(*assemble_upper(element_dofs, n, a, b, values))


def assemble_upper(element_dofs: np.ndarray, n: int, a: np.ndarray, b: np.ndarray,
                   values) -> tuple[sparse.csr_matrix, np.ndarray]:
    """The strict upper triangle (canonical CSR) and the diagonal of a symmetric matrix
    from element values of the local pairs ``a <= b``.

    Parameters
    ----------
    element_dofs : (M, n_local) ndarray of int
    n : int
        Size of the matrix.
    a, b : (K,) ndarray of int
        Local pairs, ``a <= b``.
    values : callable
        ``slice -> (K, m)`` the element entries of those pairs for a chunk of elements.

    Returns
    -------
    upper : (n, n) csr_matrix
        Canonical, entries above the diagonal only.
    diagonal : (n,) ndarray

    Only the upper triangle is gathered, in batches (the list of element entries never
    holds more than some 10^7); each batch becomes a canonical CSR matrix (duplicates
    summed) and the batches are added pairwise (a balanced tree: every entry is merged
    about log2(batches) times, not once per batch) as they come, in row blocks
    (:class:`~._sparse.PairwiseSum`: the same sums as :func:`~._sparse.sum_pairwise`).
    """
    diagonal = np.zeros(n)
    off = a != b
    k = int(off.sum())
    first, second = a[off], b[off]
    total = PairwiseSum((n, n))          # the batches summed as they come (row blocks)
    for batch in _chunks(len(element_dofs), max(CHUNK, BATCH // max(k, 1))):
        m = batch.stop - batch.start
        dofs = np.ascontiguousarray(element_dofs[batch].T, dtype=np.int32)   # (n_local, m)
        i, cols = dofs[first], dofs[second]                                # (k, m)
        rows = np.minimum(i, cols)
        np.maximum(i, cols, out=cols)
        del i
        data = np.empty((k, m))
        diagonal_values = np.empty((int((~off).sum()), m))

        def fill(chunk: slice, batch=batch, data=data,
                 diagonal_values=diagonal_values) -> None:
            part = slice(chunk.start - batch.start, chunk.stop - batch.start)
            v = values(chunk)
            data[:, part] = v[off]
            diagonal_values[:, part] = v[~off]

        for _ in _map(fill, m, batch.start):
            pass
        diagonal += np.bincount(dofs[a[~off]].ravel(), weights=diagonal_values.ravel(),
                                minlength=n)
        del diagonal_values, dofs
        total.add(sparse.csr_matrix((data.ravel(), (rows.ravel(), cols.ravel())),
                                    shape=(n, n)))
        del rows, cols, data
        total.merge()                   # with this batch's arrays and matrix freed
    upper = total.result()
    del total
    release_memory()             # the batches' pages, before the next phase counts them
    return upper, diagonal


def _field_gradients(space: Space, values: np.ndarray, part: slice, lam: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(nq, d, m) gradient of the field at barycentric points `lam`, and (m,) volumes."""
    g, vol = barycentric_gradients(space.points, space.cells[part])
    local = np.take(values, space.element_dofs[part].T)                # (k, m)
    if space.order == 1:                        # the same gradient everywhere
        coefficients = local[None]                                     # (1, d + 1, m)
    else:
        c = _shape_coefficients(space.ndim, space.order, lam)          # (nq, k, d + 1)
        coefficients = np.einsum("xkp,km->xpm", c, local)
    grad = np.zeros((coefficients.shape[0], g.shape[1], g.shape[2]))
    for p in range(g.shape[0]):
        grad += coefficients[:, p, None, :] * g[p]
    if len(lam) > grad.shape[0]:
        grad = np.broadcast_to(grad, (len(lam),) + grad.shape[1:])
    return grad, np.abs(vol)


def cell_gradients(space: Space, values: np.ndarray) -> np.ndarray:
    """(M, d) gradient of the field `values` at each element's centroid (its mean)."""
    d = space.ndim
    centroid = np.full((1, d + 1), 1.0 / (d + 1))
    out = np.empty((d, len(space.cells)))

    def fill(part: slice) -> None:
        out[:, part] = _field_gradients(space, values, part, centroid)[0][0]

    for _ in _map(fill, len(space.cells)):
        pass
    return out.T


def cell_fluxes(space: Space, values: np.ndarray, tensors: np.ndarray,
                cell_material: np.ndarray) -> tuple[np.ndarray, float]:
    """(M, d) flux ``-C grad u`` at each element's centroid (its mean), and the energy
    :func:`dissipation`, in one pass over the elements."""
    d = space.ndim
    lam, w = _quadrature(d, space.order)
    centroid = np.full((1, d + 1), 1.0 / (d + 1))
    points = lam if space.order == 1 else np.concatenate([centroid, lam])
    tensors = np.asarray(tensors, dtype=np.float64)
    out = np.empty((d, len(space.cells)))

    def fill(part: slice) -> float:
        grad, vol = _field_gradients(space, values, part, points)     # (nq, d, m)
        flux = _apply(_tensor_rows(tensors, cell_material[part]), grad)
        out[:, part] = -flux[0]
        quadrature = grad if space.order == 1 else grad[1:]
        density = w @ _dot(quadrature, flux if space.order == 1 else flux[1:])
        return float(density @ vol)

    return out.T, sum(_map(fill, len(space.cells)))


def dissipation(space: Space, values: np.ndarray, tensors: np.ndarray,
                cell_material: np.ndarray) -> float:
    """``int grad u . C grad u``, summed element by element (no cancellation).

    At the discrete solution of a potential 0/1 problem this equals the flux through
    the box times the potential difference, and its error is quadratic in the solver's
    error, whereas a sum of reactions cancels terms of both signs (with conductivities
    1e-8 and 1e8 it loses every digit). Exact quadrature for P1 and P2.
    """
    lam, w = _quadrature(space.ndim, space.order)
    tensors = np.asarray(tensors, dtype=np.float64)

    def energy(part: slice) -> float:
        grad, vol = _field_gradients(space, values, part, lam)      # (nq, d, m)
        flux = _apply(_tensor_rows(tensors, cell_material[part]), grad)
        return float((w @ _dot(grad, flux)) @ vol)

    return sum(_map(energy, len(space.cells)))


def p1_embedding(space: Space) -> sparse.csr_matrix | None:
    """(n_dofs, N) the P1 functions among the space's: a vertex keeps its value, an edge
    dof takes the mean of its two ends. None for P1 (nothing coarser to give)."""
    if space.edges is None:
        return None
    n, e = len(space.points), len(space.edges)
    rows = np.concatenate([np.arange(n), np.repeat(n + np.arange(e), 2)])
    cols = np.concatenate([np.arange(n), space.edges.ravel()])
    weights = np.concatenate([np.ones(n), np.full(2 * e, 0.5)])
    return sparse.csr_matrix((weights, (rows, cols)), shape=(n + e, n))


def cell_volumes(space: Space) -> np.ndarray:
    """(M,) signed volume (area in 2-D) of each element."""
    out = np.empty(len(space.cells))

    def fill(part: slice) -> None:
        out[part] = barycentric_gradients(space.points, space.cells[part])[1]

    for _ in _map(fill, len(space.cells)):
        pass
    return out
