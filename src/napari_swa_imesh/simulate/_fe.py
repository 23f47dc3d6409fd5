"""The bridge to scikit-fem: our meshes as its meshes, and the diffusion forms.

scikit-fem does the element work (shape functions, quadrature, sparse assembly); what is
ours is only how a :class:`~napari_swa_imesh.mesh.Mesh` becomes a scikit-fem mesh and
which quadrature is exact for piecewise-constant coefficients.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ..mesh import Mesh

__all__ = ["cell_gradients", "dissipation", "element_order", "fe_basis", "mass_basis",
           "mass_matrix",
           "stiffness_matrix", "vertex_values"]


def _skfem():
    import skfem  # imported late: it takes a second, and the CLI may not need it

    return skfem


def fe_basis(mesh: Mesh, order: int = 1):
    """A scikit-fem ``Basis`` of P1 or P2 Lagrange elements on `mesh`.

    The quadrature is exact for the stiffness of piecewise-constant coefficients
    (degree ``2 * (order - 1)``: one point per element for P1), so the assembly costs no
    more than it must. The first ``len(mesh.points)`` degrees of freedom are the vertices,
    in the mesh's vertex order.
    """
    skfem = _skfem()
    points = np.ascontiguousarray(mesh.points.T, dtype=np.float64)
    cells = np.ascontiguousarray(mesh.cells.T)
    if mesh.ndim == 2:
        fem_mesh = skfem.MeshTri(points, cells, validate=False)
        element = skfem.ElementTriP2() if order == 2 else skfem.ElementTriP1()
    else:
        fem_mesh = skfem.MeshTet(points, cells, validate=False)
        element = skfem.ElementTetP2() if order == 2 else skfem.ElementTetP1()
    return skfem.Basis(fem_mesh, element, intorder=2 * (order - 1))


def stiffness_matrix(basis, tensors: np.ndarray, cell_material: np.ndarray,
                     isotropic: bool) -> sparse.csr_matrix:
    """Assemble ``K[i, j] = sum_e int_e (C_e grad phi_j) . grad phi_i``.

    Parameters
    ----------
    basis : skfem.Basis
    tensors : (n_materials, d, d) ndarray
        Conductivity tensors in the mesh's axis order.
    cell_material : (M,) ndarray of int
        Row of `tensors` for each element.
    isotropic : bool
        Every tensor is a multiple of the identity (a cheaper form).
    """
    skfem = _skfem()
    from skfem.helpers import dot, grad, mul

    nqp = basis.X.shape[-1]
    if isotropic:
        k = tensors[:, 0, 0][cell_material]
        field = np.broadcast_to(k[:, None], (k.size, nqp))

        @skfem.BilinearForm
        def form(u, v, w):
            return w["c"] * dot(grad(u), grad(v))
    else:
        per_cell = np.moveaxis(tensors[cell_material], 0, -1)     # (d, d, M)
        field = np.broadcast_to(per_cell[..., None], per_cell.shape + (nqp,))

        @skfem.BilinearForm
        def form(u, v, w):
            return dot(mul(w["c"], grad(u)), grad(v))
    return skfem.asm(form, basis, c=np.ascontiguousarray(field)).tocsr()


def mass_basis(basis):
    """The basis with a quadrature exact for ``phi_i phi_j`` (degree ``2 * order``), and so
    for every lower-degree integrand: mass, loads and amounts of piecewise-constant data."""
    skfem = _skfem()
    return skfem.Basis(basis.mesh, basis.elem, intorder=2 * element_order(basis))


def mass_matrix(exact, capacity_per_cell: np.ndarray) -> sparse.csr_matrix:
    """Consistent mass ``M[i, j] = sum_e c_e int_e phi_i phi_j`` on a :func:`mass_basis`."""
    skfem = _skfem()
    nqp = exact.X.shape[-1]
    field = np.broadcast_to(capacity_per_cell[:, None], (capacity_per_cell.size, nqp))

    @skfem.BilinearForm
    def form(u, v, w):
        return w["c"] * u * v
    return skfem.asm(form, exact, c=np.ascontiguousarray(field)).tocsr()


def dissipation(basis, values: np.ndarray, tensors: np.ndarray,
                cell_material: np.ndarray) -> float:
    """``int grad u . C grad u``, summed element by element (no cancellation).

    At the discrete solution of a potential 0/1 problem this equals the flux through
    the box times the potential difference, and its error is quadratic in the solver's
    error, whereas a sum of reactions cancels terms of both signs (with conductivities
    1e-8 and 1e8 it loses every digit). Exact quadrature for P1 and P2.
    """
    grad = basis.interpolate(values).grad                             # (d, M, nqp)
    weights = basis.dx                                                 # (M, nqp)
    total = 0.0
    for i, tensor in enumerate(tensors):       # per material, a handful: not per element
        cells = np.flatnonzero(cell_material == i)
        g = grad[:, cells]                                             # (d, m, nqp)
        density = np.einsum("imq,ij,jmq->mq", g, tensor, g)
        total += float(np.sum(density * weights[cells]))
    return total


def element_order(basis) -> int:
    """Polynomial degree of the basis' Lagrange element (1 or 2)."""
    skfem = _skfem()
    return 2 if isinstance(basis.elem, (skfem.ElementTriP2, skfem.ElementTetP2)) else 1


def cell_gradients(basis, values: np.ndarray) -> np.ndarray:
    """(M, d) gradient of the finite-element field `values`, averaged over each element."""
    return basis.interpolate(values).grad.mean(axis=-1).T


def vertex_values(values: np.ndarray, n_points: int) -> np.ndarray:
    """A copy of the field at the mesh vertices (the first `n_points` degrees of freedom).

    A copy, not a view: callers keep it while `values` is updated in place.
    """
    return np.array(values[:n_points], dtype=np.float64, copy=True)
