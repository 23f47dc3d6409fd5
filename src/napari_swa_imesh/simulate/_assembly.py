"""Our own P1/P2 Lagrange assembly on simplices: stiffness, energy, element gradients.

scikit-fem is the reference (the tests require our stiffness to equal its matrix to
1e-12, with its numbering of the degrees of freedom); this module exists for the sizes a
128^3 image gives, ten million tetrahedra: scikit-fem keeps every element's basis
gradients and a 16-entries-per-element COO list (10 GB there), whereas here elements are
taken in chunks and only their few pair values reach a compressed matrix.

With affine simplices and a conductivity constant per element, every gradient of a P1 or
P2 basis function is ``grad phi_a = sum_p c_ap(lambda) grad lambda_p`` (``c`` constant for
P1, linear in the barycentric coordinates for P2), so the element matrix is
``vol * sum_pq Q[a, b, p, q] (grad lambda_p . C grad lambda_q)`` with ``Q`` a table
computed once from an exact quadrature of degree two.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from ..mesh import Mesh

__all__ = ["Space", "assemble_pairs", "barycentric_gradients", "cell_gradients",
           "dissipation", "fe_space", "stiffness_matrix"]

CHUNK = 1 << 16          # elements per chunk of arithmetic: temporaries of a few MB
BATCH = 1 << 21          # elements per sparse conversion: a list of some 10^7 entries

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
    points_t: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        # (d, N): the gathers below read one coordinate of many vertices at a time
        object.__setattr__(self, "points_t", np.ascontiguousarray(self.points.T))

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
    edges = np.stack([keys // n, keys % n], axis=1)
    element_dofs = np.concatenate([cells, n + inverse.reshape(lo.shape)], axis=1)
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
    """Local pairs ``a <= b`` and the (K, (d+1)^2) table from ``G`` to their entries."""
    lam, w = _quadrature(d, order)
    c = _shape_coefficients(d, order, lam)
    a, b = np.triu_indices(c.shape[1])
    q = np.einsum("x,xkp,xkr->kpr", w, c[:, a], c[:, b])       # (K, d+1, d+1)
    return a, b, q.reshape(len(a), -1)


def barycentric_gradients(points_t: np.ndarray, cells: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the barycentric coordinates, (d + 1, d, m), and volumes, (m,).

    Component-major (`points_t` is the (d, N) transposed points): every operation below
    runs on contiguous rows of m numbers, several times faster than (m, 4, 3) blocks.
    """
    x = points_t[:, cells.T]                                      # (d, d + 1, m)
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
    return g, np.abs(det) / (6.0 if d == 3 else 2.0)


def _chunks(m: int, size: int = CHUNK):
    for start in range(0, m, size):
        yield slice(start, min(start + size, m))


def _weighted_products(space: Space, part: slice, tensors: np.ndarray,
                       cell_material: np.ndarray) -> np.ndarray:
    """(m, (d+1)^2) ``vol * grad lambda_p . C grad lambda_q`` of the elements in `part`."""
    g, vol = barycentric_gradients(space.points_t, space.cells[part])
    d, m = g.shape[1], g.shape[2]
    c = tensors.reshape(len(tensors), -1).T[:, cell_material[part]]   # (d * d, m)
    c *= vol
    cg = np.empty_like(g)                                              # C grad lambda
    for q in range(d + 1):
        for i in range(d):
            np.multiply(c[i * d], g[q, 0], out=cg[q, i])
            for j in range(1, d):
                cg[q, i] += c[i * d + j] * g[q, j]
    products = np.empty((m, d + 1, d + 1))
    for p in range(d + 1):
        for q in range(p, d + 1):
            dot = g[p, 0] * cg[q, 0]
            for i in range(1, d):
                dot += g[p, i] * cg[q, i]
            products[:, p, q] = products[:, q, p] = dot
    return products.reshape(m, -1)


def stiffness_matrix(space: Space, tensors: np.ndarray, cell_material: np.ndarray
                     ) -> sparse.csr_matrix:
    """Assemble ``K[i, j] = sum_e int_e (C_e grad phi_j) . grad phi_i`` (CSR, symmetric).

    Parameters
    ----------
    space : Space
    tensors : (n_materials, d, d) ndarray
        Conductivity tensors in the mesh's axis order.
    cell_material : (M,) ndarray of int
        Row of `tensors` for each element.
    """
    a, b, table = _pair_table(space.ndim, space.order)
    tensors = np.asarray(tensors, dtype=np.float64)

    def values(part: slice) -> np.ndarray:
        return _weighted_products(space, part, tensors, cell_material) @ table.T

    return assemble_pairs(space.element_dofs, space.n_dofs, a, b, values)


def assemble_pairs(element_dofs: np.ndarray, n: int, a: np.ndarray, b: np.ndarray,
                   values) -> sparse.csr_matrix:
    """A symmetric CSR matrix from element values of the local pairs ``a <= b``.

    Parameters
    ----------
    element_dofs : (M, n_local) ndarray of int
    n : int
        Size of the matrix.
    a, b : (K,) ndarray of int
        Local pairs, ``a <= b``.
    values : callable
        ``slice -> (m, K)`` the element entries of those pairs for a chunk of elements.

    Only the upper triangle is gathered (in batches, so the list of element entries never
    holds more than a few million), then mirrored.
    """
    diagonal = np.zeros(n)
    off = a != b
    k = int(off.sum())
    upper = sparse.csr_matrix((n, n))
    for batch in _chunks(len(element_dofs), BATCH):
        m = batch.stop - batch.start
        rows = np.empty((m, k), dtype=np.int32)
        cols = np.empty((m, k), dtype=np.int32)
        data = np.empty((m, k))
        for part in _chunks(m):
            chunk = slice(batch.start + part.start, batch.start + part.stop)
            v = values(chunk)
            dofs = element_dofs[chunk]
            diagonal += np.bincount(dofs[:, a[~off]].ravel(), weights=v[:, ~off].ravel(),
                                    minlength=n)
            i, j = dofs[:, a[off]], dofs[:, b[off]]
            np.minimum(i, j, out=rows[part], casting="unsafe")
            np.maximum(i, j, out=cols[part], casting="unsafe")
            data[part] = v[:, off]
        upper = upper + sparse.csr_matrix((data.ravel(), (rows.ravel(), cols.ravel())),
                                          shape=(n, n))
        del rows, cols, data
    full = upper + upper.T.tocsr()
    del upper
    full = full + sparse.diags(diagonal, format="csr")
    full.sort_indices()
    return full


def _field_gradients(space: Space, values: np.ndarray, part: slice, lam: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(nq, d, m) gradient of the field at barycentric points `lam`, and (m,) volumes."""
    g, vol = barycentric_gradients(space.points_t, space.cells[part])
    c = _shape_coefficients(space.ndim, space.order, lam)            # (nq, k, d + 1)
    s = values[space.element_dofs[part]] @ c.transpose(1, 0, 2).reshape(c.shape[1], -1)
    s = s.reshape(-1, len(lam), g.shape[0])                          # (m, nq, d + 1)
    grad = np.zeros((len(lam),) + g.shape[1:])
    for p in range(g.shape[0]):
        grad += s[:, :, p].T[:, None, :] * g[p][None]
    return grad, vol


def cell_gradients(space: Space, values: np.ndarray) -> np.ndarray:
    """(M, d) gradient of the field `values` at each element's centroid (its mean)."""
    d = space.ndim
    centroid = np.full((1, d + 1), 1.0 / (d + 1))
    out = np.empty((len(space.cells), d))
    for part in _chunks(len(space.cells)):
        out[part] = _field_gradients(space, values, part, centroid)[0][0].T
    return out


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
    total = 0.0
    for part in _chunks(len(space.cells)):
        grad, vol = _field_gradients(space, values, part, lam)      # (nq, d, m)
        c = tensors[cell_material[part]]                            # (m, d, d)
        flux = np.einsum("mij,xjm->xim", c, grad)
        density = np.einsum("xim,xim,x->m", grad, flux, w)
        total += float(density @ vol)
    return total
