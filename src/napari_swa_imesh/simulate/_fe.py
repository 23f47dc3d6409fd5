"""The bridge to scikit-fem: our meshes as its meshes, the mass and load forms.

The stiffness, the dissipated energy and the element gradients are ours
(:mod:`._assembly`: vectorised, in chunks, ten million tetrahedra in seconds); scikit-fem
does the rest of the element work (facet integrals, mass matrices, loads) with the same
numbering of the degrees of freedom, and is the tests' reference for our stiffness.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ..mesh import Mesh

__all__ = ["element_order", "fe_basis", "mass_basis", "mass_matrix", "vertex_values"]


def _skfem():
    import skfem  # imported late: it takes a second, and the CLI may not need it

    return skfem


def fe_basis(mesh: Mesh, order: int = 1):
    """A scikit-fem ``Basis`` of P1 or P2 Lagrange elements on `mesh`.

    The quadrature is exact for the stiffness of piecewise-constant coefficients
    (degree ``2 * (order - 1)``: one point per element for P1). The first
    ``len(mesh.points)`` degrees of freedom are the vertices, in the mesh's vertex order;
    the numbering is that of :func:`~._assembly.fe_space` (tested).
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


def element_order(basis) -> int:
    """Polynomial degree of the basis' Lagrange element (1 or 2)."""
    skfem = _skfem()
    return 2 if isinstance(basis.elem, (skfem.ElementTriP2, skfem.ElementTetP2)) else 1


def vertex_values(values: np.ndarray, n_points: int) -> np.ndarray:
    """A copy of the field at the mesh vertices (the first `n_points` degrees of freedom).

    A copy, not a view: callers keep it while `values` is updated in place.
    """
    return np.array(values[:n_points], dtype=np.float64, copy=True)
