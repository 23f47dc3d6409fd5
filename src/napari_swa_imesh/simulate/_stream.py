"""A sharper lower bound of k_eff in 2-D: the flux as the rotated gradient of a stream function.

In the plane every divergence-free flux is ``s = J grad psi`` (``J`` the rotation by a
right angle, ``s_a = d psi / d x_b`` along the flow axis ``a``, ``s_b = -d psi / d x_a``)
for a stream function ``psi``. The dual principle of :mod:`._dual` (``Q >= Phi(s)^2 / E(s)``,
``E(s) = int s . C^-1 s``, for every ``s`` in H(div) with ``div s = 0`` and ``s . n = 0`` on
the insulated boundary) then becomes a problem of the primal's kind, solved with the
primal's own elements (P2 for P2): minimise ``int grad psi . (J^T C^-1 J) grad psi``.

**Why every such psi gives a bound** (the proof; nothing here depends on the solver's
tolerance). Let ``psi`` be continuous and piecewise polynomial on the mesh (P1 or P2),
constant on each connected part of the insulated boundary (every boundary facet not on
the two fixed faces; its vertex and edge dofs collapsed to one unknown per part), and
``s = J grad psi``. On one element T and any H1 function v, integration by parts gives
``int_T s . grad v = int_dT v s . n_T`` (``div s = d_a d_b psi - d_b d_a psi = 0`` in T),
and on an edge ``s . n_T = d psi / d t`` is the derivative of psi along the edge (tangent
``t = J^T n_T``), the same from both sides because psi is continuous. Summed over the
elements, the interior edges cancel, the insulated ones vanish (psi is constant along
them), and for the exact potential u (0 on the ``min`` face, 1 on the ``max`` face)

    ``int s . grad u = Phi := sum over the max face's edges of (psi(end) - psi(start))``,

the total flux of s through the ``max`` face. Cauchy-Schwarz in the C-weighted product,
``Phi^2 = (int s . grad u)^2 <= int s . C^-1 s * int grad u . C grad u = E(s) Q``, is
``Q >= Phi^2 / E(s)``: a lower bound for any such psi, converged or not, computed here
with psi's energy integrated exactly (degree-two quadrature of P1 gradients) and Phi
read off psi's values. The flux through the ``min`` face is the same sum there; the two
must agree to round-off (they do by the same telescoping), else no bound is claimed and
the caller falls back to :func:`._dual.dual_bound`.

With P2, ``J grad psi`` spans the divergence-free fields of the second-order
Raviart-Thomas space (RT1) on a simply connected mesh, so the bound is the mixed RT1
solution's: the error of its energy falls like the primal P2's, where the
Crouzeix-Raviart / RT0 flux of :mod:`._dual` is piecewise constant and stays far below
the truth at high contrast. Holes (excluded materials, insulated) keep one free constant
each. Which constant the insulated parts take is free for the proof; the parts that touch
the ``min`` side of the other axis are set to 0 and those that touch its ``max`` side to 1
(the box's two insulated sides), the others are unknowns of the solve. A part touching
both sides separates the fixed faces (no flux crosses in 2-D); a mesh without such sides
is left to the Crouzeix-Raviart bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from ..mesh import Mesh
from ._assembly import (
    Space,
    _apply,
    _dot,
    _field_gradients,
    _map,
    _quadrature,
    _tensor_rows,
    p1_embedding,
    stiffness_matrix,
)
from ._dual import FacetTable, element_energies, facet_table
from ._solve import DirichletSolver, SolverInfo, connected_parts

__all__ = ["StreamBound", "stream_bound"]

#: Relative disagreement of the flux read on the two fixed faces above which no bound is
#: claimed (the telescoping sums agree to round-off, about 1e-14).
FACE_TOLERANCE = 1e-8


@dataclass(frozen=True)
class StreamBound:
    """The stream-function (lower) bound of one mixed-boundary solve.

    Attributes
    ----------
    k_lower : float
        ``Phi^2 / E * L / A``: a lower bound of k_eff.
    psi : (n_dofs,) ndarray
        The stream function on the primal's space (collapsed dofs expanded).
    scale : float
        ``Phi / E``: ``scale * J grad psi`` is the optimally scaled flux (complementary
        energy ``Q_lower``).
    rotation : (2, 2) ndarray
        ``J`` in mesh axis order.
    info : SolverInfo
    unknowns : int
        Unknowns of the stream-function solve.
    """

    k_lower: float
    psi: np.ndarray
    scale: float
    rotation: np.ndarray
    info: SolverInfo
    unknowns: int

    def hypercircle(self, space: Space, values: np.ndarray, tensors: np.ndarray,
                    cell_material: np.ndarray) -> np.ndarray:
        """(M,) ``int_T (s - C grad u) . C^-1 (s - C grad u)``, ``s`` the scaled flux and
        `values` the primal potential on `space` (the space psi lives on): the gap per
        element, summing to ``Q_upper - Q_lower`` (Prager-Synge)."""
        lam, w = _quadrature(space.ndim, space.order)
        tensors = np.asarray(tensors, dtype=np.float64)
        inverse = np.linalg.inv(tensors)
        out = np.empty(len(space.cells))
        rot = self.rotation

        def fill(part: slice) -> None:
            gu, vol = _field_gradients(space, values, part, lam)           # (nq, d, m)
            gp = _field_gradients(space, self.psi, part, lam)[0]
            s = self.scale * np.einsum("ij,qjm->qim", rot, gp)
            diff = s - _apply(_tensor_rows(tensors, cell_material[part]), gu)
            density = _dot(diff, _apply(_tensor_rows(inverse, cell_material[part]), diff))
            out[part] = (w @ density) * vol

        for _ in _map(fill, len(space.cells)):
            pass
        return np.maximum(out, 0.0)


def _rotation(axis: int) -> np.ndarray:
    """``J`` with ``(J g)_axis = g_other`` and ``(J g)_other = -g_axis`` (mesh order)."""
    other = 1 - axis
    j = np.zeros((2, 2))
    j[axis, other] = 1.0
    j[other, axis] = -1.0
    return j


def _on_plane(points: np.ndarray, vertices: np.ndarray, axis: int, value: float,
              eps: float) -> np.ndarray:
    return (np.abs(points[vertices, axis] - value) <= eps).all(axis=1)


def _edge_dofs(space: Space, pairs: np.ndarray) -> np.ndarray:
    """P2 dof of each sorted vertex pair (an edge of the mesh)."""
    n = len(space.points)
    assert space.edges is not None
    keys = space.edges[:, 0].astype(np.int64) * n + space.edges[:, 1]
    wanted = pairs[:, 0].astype(np.int64) * n + pairs[:, 1]
    return n + np.searchsorted(keys, wanted)


def _collapse(space: Space, facets: FacetTable, insulated: np.ndarray, group: np.ndarray,
              n_groups: int) -> tuple[np.ndarray, int]:
    """Reduced index of every dof: the vertices first (a group of insulated boundary
    parts is one of them), then the edges; an edge on an insulated facet takes its
    part's index. Returns ``(index (n_dofs,), number of reduced vertex unknowns)``."""
    n = len(space.points)
    vertex_group = np.full(n, -1, dtype=np.intp)
    vertex_group[facets.vertices[insulated].ravel()] = np.repeat(group, 2)
    plain = vertex_group < 0
    index = np.empty(space.n_dofs, dtype=np.intp)
    index[:n][plain] = n_groups + np.arange(int(plain.sum()))
    index[:n][~plain] = vertex_group[~plain]
    n_vertex = n_groups + int(plain.sum())
    if space.edges is not None:
        on = np.zeros(space.n_dofs, dtype=bool)
        dofs = _edge_dofs(space, facets.vertices[insulated])
        on[dofs] = True
        edges = np.arange(n, space.n_dofs)
        loose = edges[~on[n:]]
        index[loose] = n_vertex + np.arange(loose.size)
        index[dofs] = group
    return index, n_vertex


def stream_bound(mesh: Mesh, space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                 axis: int, lo: np.ndarray, hi: np.ndarray, *, tol: float,
                 facets: FacetTable | None = None) -> StreamBound | None:
    """The lower bound of k_eff along `axis` (mesh axis order) from a stream function.

    Parameters
    ----------
    mesh : Mesh
        A triangle mesh.
    space : Space
        The primal's space (P1 or P2); the stream function uses the same elements.
    tensors : (n_materials, 2, 2) ndarray
        Conductivities, mesh axis order (invertible).
    cell_material : (M,) ndarray of int
    axis : int
        Mesh axis of the flow (0 = row, 1 = column).
    lo, hi : (2,) ndarray
        The box.
    tol : float
        Relative residual of the solve (the bound holds whatever it is).
    facets : FacetTable, optional
        :func:`._dual.facet_table` of the mesh, reused across axes.

    Returns
    -------
    StreamBound or None
        None where this construction does not apply (not 2-D, no insulated part on one
        of the box's sides, or the two faces' fluxes disagree): use the
        Crouzeix-Raviart bound instead. ``k_lower = 0`` when an insulated part joins
        both sides (it cuts the fixed faces apart: no flux crosses).
    """
    if mesh.ndim != 2:
        return None
    facets = facet_table(mesh.cells) if facets is None else facets
    other = 1 - axis
    points = space.points
    eps = 1e-9 * float(np.max(hi - lo))
    boundary = facets.boundary
    fixed_low = boundary & _on_plane(points, facets.vertices, axis, lo[axis], eps)
    fixed_high = boundary & _on_plane(points, facets.vertices, axis, hi[axis], eps)
    insulated = np.flatnonzero(boundary & ~fixed_low & ~fixed_high)
    if not insulated.size or not fixed_low.any() or not fixed_high.any():
        return None
    # connected parts of the insulated boundary (facets sharing a vertex)
    ends = facets.vertices[insulated]
    n = len(points)
    graph = sparse.csr_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])), shape=(n, n))
    part_of_vertex = csgraph.connected_components(graph, directed=False)[1]
    part = part_of_vertex[ends[:, 0]]
    labels, part = np.unique(part, return_inverse=True)
    side_low = _on_plane(points, ends, other, lo[other], eps)
    side_high = _on_plane(points, ends, other, hi[other], eps)
    at_low = np.zeros(labels.size, dtype=bool)
    at_high = np.zeros(labels.size, dtype=bool)
    at_low[part[side_low]] = True
    at_high[part[side_high]] = True
    if not at_low.any() or not at_high.any():
        return None
    rotation = _rotation(axis)
    if (at_low & at_high).any():
        return StreamBound(0.0, np.zeros(space.n_dofs), 0.0, rotation,
                           SolverInfo(0, 0, 0.0, 0.0), 0)
    # groups: 0 = the min side's parts, 1 = the max side's, then one per other part
    free_parts = np.flatnonzero(~at_low & ~at_high)
    group_of_part = np.where(at_low, 0, 1)
    group_of_part[free_parts] = 2 + np.arange(free_parts.size)
    n_groups = 2 + free_parts.size
    index, n_vertex = _collapse(space, facets, insulated, group_of_part[part], n_groups)
    n_reduced = int(index.max()) + 1
    collapse = sparse.csr_matrix((np.ones(space.n_dofs), (np.arange(space.n_dofs), index)),
                                 shape=(space.n_dofs, n_reduced))
    inverse = np.linalg.inv(np.asarray(tensors, dtype=np.float64))
    rotated = np.einsum("ji,mjk,kl->mil", rotation, inverse, rotation)    # J^T C^-1 J
    matrix = (collapse.T @ stiffness_matrix(space, rotated, cell_material) @ collapse).tocsr()
    # parts of the reduced problem without a held value float: pin one unknown each
    parts = connected_parts(matrix)
    held_part = np.zeros(parts.max() + 1, dtype=bool)
    held_part[parts[[0, 1]]] = True
    _, pins = np.unique(parts, return_index=True)
    pins = pins[~held_part[parts[pins]]]
    held = np.concatenate([[0, 1], pins]).astype(np.intp)
    values = np.zeros(held.size)
    values[1] = 1.0
    coarse = None
    embedding = p1_embedding(space)
    if embedding is not None:        # the P1 functions of the collapsed vertices
        representative = np.empty(n_reduced, dtype=np.intp)
        representative[index] = np.arange(space.n_dofs)
        vertex_collapse = collapse[:n][:, :n_vertex]
        coarse = (embedding[representative] @ vertex_collapse).tocsr()
    solver = DirichletSolver(matrix, held, tol=tol, coarse=coarse)
    reduced, info = solver.solve(values)
    del solver, matrix, coarse
    psi = reduced[index]
    energy = float(element_energies(space, psi, rotated, cell_material)[0].sum())
    flux = []
    for face in (fixed_low, fixed_high):       # sum of psi(end) - psi(start) along +other
        v = facets.vertices[face]
        forward = points[v[:, 1], other] >= points[v[:, 0], other]
        start = np.where(forward, v[:, 0], v[:, 1])
        end = np.where(forward, v[:, 1], v[:, 0])
        flux.append(float(np.sum(psi[end] - psi[start])))
    phi = flux[1]
    if not energy > 0 or not abs(phi) > 0:
        return StreamBound(0.0, psi, 0.0, rotation, info, n_reduced)
    if abs(flux[0] - phi) > FACE_TOLERANCE * abs(phi):
        return None
    length = hi[axis] - lo[axis]
    area = float(hi[other] - lo[other])
    return StreamBound(float(phi * phi / energy * length / area), psi, phi / energy,
                       rotation, info, n_reduced)
