"""The periodic-fluctuation protocol: the full effective conductivity tensor.

For each axis i the potential is ``u_i = x_i + w_i`` with the fluctuation ``w_i``
periodic over the box (equal on opposite faces): a mean gradient of one along x_i and
no preferred face. Then ``K_ji = (1/V) x_j . A u_i`` where ``A`` is the stiffness
matrix: ``A x_j`` assembles ``int grad(phi) . k e_j`` because the coordinate function
is exactly a finite-element function, so no other form is assembled. The fluctuation
solves ``P^T A P w = -P^T A x_i``, where ``P`` copies each degree of freedom on a
``max`` face from its partner on the ``min`` face (and box edges and corners from theirs).

The mesh must have the same degrees of freedom on opposite faces, translated, and its
facets there must be cut alike (matched nodes under different triangles give traces that
differ between the faces: not periodic, and no error would show it): the IMESH mesh of
``mesh_labels(..., periodic=True)`` has both; any other mesh is checked and refused with
a sentence if it has not.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ._solve import DEFAULT_TOLERANCE, SolverInfo, SPDSolver, connected_parts, split_fixed

__all__ = ["PeriodicProblem", "periodic_map", "check_face_facets"]


def periodic_map(dof_coordinates: np.ndarray, lo: np.ndarray, hi: np.ndarray
                 ) -> tuple[np.ndarray, int]:
    """Each degree of freedom's representative when opposite box faces are identified.

    Parameters
    ----------
    dof_coordinates : (d, n) ndarray
        Coordinates of the degrees of freedom (image axis order).
    lo, hi : (d,) ndarray
        Corners of the box.

    Returns
    -------
    reduced : (n,) ndarray of intp
        Index of each dof among the dofs off every ``max`` face (``0 .. n_reduced-1``).
    n_reduced : int

    Raises
    ------
    ValueError
        When a dof on a ``max`` face has no partner on the ``min`` face (the mesh's
        opposite faces differ).
    """
    extent = hi - lo
    tol = 1e-9 * extent[:, None]
    at_max = np.abs(dof_coordinates - hi[:, None]) <= tol                # (d, n)
    canonical = np.where(at_max, lo[:, None], dof_coordinates)
    # integer keys on a grid far finer than any element: exact matching, no float ==
    keys = np.rint((canonical - lo[:, None]) / (1e-7 * extent[:, None])).astype(np.int64).T
    off_max = ~at_max.any(axis=0)
    classes, reduced = np.unique(keys, axis=0, return_inverse=True)
    reduced = reduced.ravel().astype(np.intp)
    own = np.bincount(reduced[off_max], minlength=len(classes))
    if (own > 1).any():
        raise ValueError("two degrees of freedom share a position: the mesh is not "
                         "conforming, so opposite faces cannot be matched.")
    # a dof on m box faces has 2^m images (itself included): on a face 2, on an edge 4
    on_faces = (at_max | (np.abs(dof_coordinates - lo[:, None]) <= tol)).sum(axis=0)
    size = np.bincount(reduced, minlength=len(classes))
    unmatched = size[reduced] != np.left_shift(1, on_faces)
    if (own == 0).any() or unmatched.any():
        missing = int(np.count_nonzero(unmatched))
        raise ValueError(
            f"{missing} degree(s) of freedom on the box faces have no partner on the "
            "opposite face: the mesh is not periodic. Mesh the labels with periodic=True "
            "(swa-imesh mesh --periodic), or use the mixed protocol.")
    return reduced, int(len(classes))


def check_face_facets(cell_vertices: np.ndarray, dof_coordinates: np.ndarray,
                      lo: np.ndarray, hi: np.ndarray, reduced: np.ndarray) -> None:
    """Refuse a mesh whose opposite box faces carry different facets.

    Parameters
    ----------
    cell_vertices : (d + 1, m) ndarray of int
        The vertex dofs of every element.
    dof_coordinates : (d, n) ndarray
    lo, hi : (d,) ndarray
        Box corners.
    reduced : (n,) ndarray of intp
        :func:`periodic_map`'s representative of every dof.

    Raises
    ------
    ValueError
        When some facet on a ``min`` face has no translated twin on the ``max`` face, or
        the other way round.
    """
    d = dof_coordinates.shape[0]
    tol = 1e-9 * (hi - lo)
    rows = np.arange(d + 1)
    for axis in range(d):
        x = dof_coordinates[axis]
        sides = []
        for plane in (lo[axis], hi[axis]):
            on = np.abs(x - plane) <= tol[axis]
            # only elements with d vertices on the plane can have a facet there
            near = cell_vertices[:, on[cell_vertices].sum(axis=0) >= d]
            found = []
            for drop in rows:                      # the facet opposite vertex `drop`
                verts = near[rows != drop]
                found.append(reduced[verts[:, on[verts].all(axis=0)]].T)
            facets = np.sort(np.concatenate(found), axis=1)
            sides.append(facets[np.lexsort(facets.T[::-1])])
        if sides[0].shape != sides[1].shape or not np.array_equal(sides[0], sides[1]):
            name = "xyz"[d - 1 - axis] if d <= 3 else f"axis {axis}"
            raise ValueError(
                f"the mesh's faces at {name}min and {name}max have their nodes in the same "
                "places but are cut into different facets, so the field cannot be periodic "
                "across them: mesh the labels with periodic=True (swa-imesh mesh "
                "--periodic), or use the mixed protocol.")


class PeriodicProblem:
    """The folded system of one mesh, solved for one mean gradient at a time.

    The folded matrix and its pinned dofs do not depend on the axis, so one multigrid
    hierarchy, built here, serves every axis.

    Parameters
    ----------
    matrix : (n, n) sparse matrix
        Assembled stiffness of the whole mesh.
    dof_coordinates : (d, n) ndarray
        Coordinates of the dofs in image axis order (scikit-fem's ``doflocs``).
    lo, hi : (d,) ndarray
        Box corners.
    tol : float
        Relative residual of each solve.
    cell_vertices : (d + 1, m) ndarray of int, optional
        The vertex dofs of every element: then the facets on opposite faces are checked
        to match (:func:`check_face_facets`), not only the dofs.
    """

    def __init__(self, matrix: sparse.csr_matrix, dof_coordinates: np.ndarray,
                 lo: np.ndarray, hi: np.ndarray, *, tol: float = DEFAULT_TOLERANCE,
                 cell_vertices: np.ndarray | None = None):
        n = matrix.shape[0]
        reduced, n_reduced = periodic_map(dof_coordinates, lo, hi)
        if cell_vertices is not None:
            check_face_facets(cell_vertices, dof_coordinates, lo, hi, reduced)
        self.matrix, self.coordinates = matrix, dof_coordinates
        self.copy = sparse.csr_matrix((np.ones(n), (np.arange(n), reduced)),
                                      shape=(n, n_reduced))
        self.folded = (self.copy.T @ matrix @ self.copy).tocsr()
        # the fluctuation is free up to a constant per connected part: pin one dof each
        _, self.pins = np.unique(connected_parts(self.folded), return_index=True)
        self.volume = float(np.prod(hi - lo))
        # the pins hold 0: no coupling term, only the free block is solved
        self.free, reduced, _ = split_fixed(self.folded, self.pins)
        self.solver = SPDSolver(reduced, tol=tol, overwrite=True)
        self._setup = self.solver.setup_seconds          # reported with the first solve

    def solve(self, axis: int, *, tol: float | None = None
              ) -> tuple[np.ndarray, np.ndarray, SolverInfo]:
        """Column `axis` of the tensor (image axis order), the potential, the solve's report.

        ``K[j, axis] = (1/V) x_j . A u`` with ``u = x_axis + P w``: the mean flux under a
        unit mean gradient, as a conductivity. `tol` overrides the constructor's.
        """
        if tol is not None:
            self.solver.tol = tol
        x = self.coordinates[axis]
        rhs = -(self.copy.T @ (self.matrix @ x))
        w = np.zeros(self.folded.shape[0])
        w[self.free], info = self.solver.solve(rhs[self.free])
        info = SolverInfo(info.unknowns, info.iterations, info.residual,
                          info.seconds + self._setup, self._setup)
        self._setup = 0.0
        u = x + self.copy @ w
        column = self.coordinates @ (self.matrix @ u) / self.volume
        return column, u, info
