"""The lower bound of k_eff: an exactly divergence-free flux and its complementary energy.

For the mixed-boundary protocol along an axis (potential 0 on the ``min`` face, 1 on the
``max`` face, every other boundary of the mesh insulated: the box sides and the surfaces of
excluded materials), the flux through the box ``Q`` (``k_eff = Q L / A``) satisfies two
complementary principles:

* **primal** (upper): ``Q <= int grad v . C grad v`` for every ``v`` in H1 that is 0 and 1
  on the two faces. The conforming P1/P2 solution is such a ``v`` (its face values are set
  exactly), so its energy bounds ``Q`` from above whether or not the solver converged.
* **dual** (lower): ``Q >= Phi(s)^2 / int s . C^-1 s`` for every flux ``s`` in H(div) with
  ``div s = 0`` in the mesh, ``s . n = 0`` on every insulated boundary, and ``Phi(s)`` its
  total through the ``max`` face (maximise ``2 t Phi - t^2 int s C^-1 s`` over the scale t
  of the complementary energy).

The flux here comes from the Crouzeix-Raviart (non-conforming P1, one unknown per facet)
solution ``w`` of the same problem: by Marini's identity, ``s = C grad_h w`` is, for
piecewise-constant C and no sources, the lowest-order Raviart-Thomas mixed solution
(RT0 x P0): constant per element with a continuous normal flux, because the CR equation of
a facet is exactly the balance of the normal fluxes of its two elements. The iterative
solve leaves that balance off by its residual, so the facet fluxes are averaged across
each facet, set to 0 on the insulated boundary, and the remaining element imbalances
(round-off times the residual) are routed to the fixed faces along a spanning tree of the
elements (:func:`_route_to_faces`): the flux whose energy is taken is divergence free to
floating-point round-off, not to the solver's tolerance, and the bound is a bound.
Elements not connected through facets to a fixed face carry no flux (exactly so in the
continuum: a contact at an edge or a point carries none).

Both bounds are of the meshed geometry (the materials as the mesh places them), with the
conductivities given; on an IMESH template mesh that is the label image's voxels.

The element-wise Prager-Synge hypercircle
``eta_T = int_T (s_hat - C grad u) . C^-1 (s_hat - C grad u)`` (``s_hat`` the dual flux at
its optimal scale, u the primal solution) sums to exactly ``Q_upper - Q_lower``: it says
where the gap is, and refinement marks by it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from ..mesh import Mesh
from ._assembly import (
    Space,
    _apply,
    _dot,
    _field_gradients,
    _gradient_products,
    _map,
    _quadrature,
    _tensor_rows,
    assemble_pairs,
    barycentric_gradients,
)
from ._solve import SolverInfo, SPDSolver, connected_parts, split_fixed

__all__ = ["DualBound", "FacetTable", "dual_bound", "element_energies", "facet_table",
           "hypercircle"]

#: Relative disagreement of the flux through the two fixed faces above which the routed
#: flux is refused (round-off is about 1e-13; anything larger is a bug).
ROUTE_TOLERANCE = 1e-8


@dataclass(frozen=True)
class FacetTable:
    """The facets of a simplex mesh: the Crouzeix-Raviart degrees of freedom.

    Attributes
    ----------
    of_cell : (M, d + 1) ndarray of intp
        Facet of each element opposite each of its corners.
    owners : (F, 2) ndarray of intp
        The elements on either side (``-1`` for the second on the boundary).
    vertices : (F, d) ndarray of intp
        The facet's vertices (sorted).
    cache : dict
        What the bounds of one mesh share across axes (the curl's matrix).
    """

    of_cell: np.ndarray
    owners: np.ndarray
    vertices: np.ndarray
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def boundary(self) -> np.ndarray:
        return self.owners[:, 1] < 0


def facet_table(cells: np.ndarray) -> FacetTable:
    """Number the facets of `cells` (M, d + 1); a facet of three elements is refused."""
    cells = np.asarray(cells, dtype=np.intp)
    m, k = cells.shape
    corners = np.arange(k)
    # (M, d+1, d): the facet opposite each corner, vertices sorted
    local = np.sort(np.stack([cells[:, corners != c] for c in corners], axis=1), axis=2)
    rows = local.reshape(-1, k - 1)
    order = np.lexsort(rows.T[::-1])
    ranked = rows[order]
    new = np.ones(len(ranked), dtype=bool)
    new[1:] = (ranked[1:] != ranked[:-1]).any(axis=1)
    ids = np.cumsum(new) - 1
    facet = np.empty(len(rows), dtype=np.intp)
    facet[order] = ids
    n = int(ids[-1]) + 1
    count = np.bincount(facet, minlength=n)
    if (count > 2).any():
        raise ValueError("a facet is shared by three or more elements: the mesh is not a "
                         "manifold, so no flux can be balanced on it; mesh the labels again.")
    owner_of_row = np.repeat(np.arange(m), k)
    owners = np.full((n, 2), -1, dtype=np.intp)
    first = np.zeros(n, dtype=bool)
    by_facet = np.argsort(facet, kind="stable")           # rows of one facet together,
    starts = np.searchsorted(facet[by_facet], np.arange(n))   # the lower element first
    owners[:, 0] = owner_of_row[by_facet[starts]]
    two = count == 2
    owners[two, 1] = owner_of_row[by_facet[starts[two] + 1]]
    del first
    return FacetTable(facet.reshape(m, k), owners, ranked[new])


@dataclass(frozen=True)
class DualBound:
    """The dual (lower) bound of one mixed-boundary solve.

    Attributes
    ----------
    k_lower : float
        ``Phi^2 / E * L / A``: a lower bound of k_eff.
    flux : (M, d) ndarray
        The divergence-free flux per element (``C grad w``, mesh axis order), scaled to
        the optimum (its complementary energy equals ``Q_lower``).
    imbalance : float
        Largest element imbalance the routing removed, relative to the flux through the
        box (the CR solve's residual, seen as a flux).
    info : SolverInfo
    unknowns : int
        Facets (the CR degrees of freedom).
    """

    k_lower: float
    flux: np.ndarray
    imbalance: float
    info: SolverInfo
    unknowns: int

    def hypercircle(self, space: Space, values: np.ndarray, tensors: np.ndarray,
                    cell_material: np.ndarray) -> np.ndarray:
        """(M,) the gap per element against the primal potential `values` on `space`
        (:func:`hypercircle`)."""
        return hypercircle(space, values, self.flux, tensors, cell_material)


def _cr_stiffness(space: Space, facets: FacetTable, tensors: np.ndarray,
                  cell_material: np.ndarray) -> sparse.csr_matrix:
    """``K[F, G] = sum_T int_T C grad phi_G . grad phi_F`` for the CR functions
    ``phi_k = 1 - d lambda_k`` (1 at the midpoint of the facet opposite corner k): the P1
    element matrix times ``d^2``, on the facets."""
    d = space.ndim
    a, b = np.triu_indices(d + 1)
    tensors = np.asarray(tensors, dtype=np.float64)

    def values(part: slice) -> np.ndarray:
        return (d * d) * _gradient_products(space, part, tensors, cell_material)

    return assemble_pairs(facets.of_cell, len(facets.owners), a, b, values)


def _fixed_facets(points: np.ndarray, facets: FacetTable, axis: int, lo: np.ndarray,
                  hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boundary facets with every vertex on the ``min`` / ``max`` plane of `axis`."""
    eps = 1e-9 * (hi[axis] - lo[axis])
    on = facets.boundary
    coord = points[facets.vertices, axis]                       # (F, d)
    low = np.flatnonzero(on & (coord <= lo[axis] + eps).all(axis=1))
    high = np.flatnonzero(on & (coord >= hi[axis] - eps).all(axis=1))
    return low, high


def _cr_coarse(facets: FacetTable, n_vertices: int, free: np.ndarray,
               fixed_vertices: np.ndarray) -> sparse.csr_matrix:
    """The P1 functions among the CR ones (a facet takes the mean of its vertices),
    restricted to the free facets and to the vertices off the fixed faces: the
    multigrid's first coarse level."""
    f, d = facets.vertices.shape
    e = sparse.csr_matrix((np.full(f * d, 1.0 / d), (np.repeat(np.arange(f), d),
                                                     facets.vertices.ravel())),
                          shape=(f, n_vertices))
    keep = np.ones(n_vertices, dtype=bool)
    keep[fixed_vertices] = False
    return e[free][:, keep].tocsr()


def _route_to_faces(excess: np.ndarray, facets: FacetTable, fixed: np.ndarray,
                    anchored: np.ndarray) -> np.ndarray:
    """Facet fluxes (out of each facet's first owner) that remove every element's `excess`
    outflow, carried along a breadth-first spanning tree to the fixed facets.

    Parameters
    ----------
    excess : (M,) ndarray
        Net outflow to remove per element (zero sum is not required: the fixed faces
        absorb the rest).
    facets : FacetTable
    fixed : (k,) ndarray of intp
        Facets where the flux is free (the fixed-potential faces).
    anchored : (M,) ndarray of bool
        Elements connected through facets to a fixed one (the others are not routed).
    """
    m = len(facets.of_cell)
    inner = np.flatnonzero(~facets.boundary)
    a, b = facets.owners[inner, 0], facets.owners[inner, 1]
    # one fixed facet per element links it to the root node m
    root_cells, first = np.unique(facets.owners[fixed, 0], return_index=True)
    root_facets = fixed[first]
    u = np.concatenate([a, root_cells])
    v = np.concatenate([b, np.full(len(root_cells), m)])
    edge_facet = np.concatenate([inner, root_facets])
    graph = sparse.csr_matrix((np.ones(len(u)), (u, v)), shape=(m + 1, m + 1))
    order, parent = csgraph.breadth_first_order(graph, m, directed=False,
                                                return_predecessors=True)
    depth = np.full(m + 1, -1, dtype=np.intp)
    depth[m] = 0
    # breadth-first order: each node after its parent; depths by levels of the order
    nodes = order[1:]
    depth_of = csgraph.shortest_path(graph, indices=m, unweighted=True, directed=False)
    depth[nodes] = depth_of[nodes].astype(np.intp)
    # the facet of each tree edge (child, parent): look the pair up among the edges
    keys = np.minimum(u, v).astype(np.int64) * (m + 1) + np.maximum(u, v)
    sort = np.argsort(keys)
    child = nodes
    pair = (np.minimum(child, parent[child]).astype(np.int64) * (m + 1)
            + np.maximum(child, parent[child]))
    facet_of_child = edge_facet[sort[np.searchsorted(keys[sort], pair)]]
    carried = np.zeros(m + 1)
    carried[:m] = np.where(anchored, excess, 0.0)
    by_depth = child[np.argsort(-depth[child], kind="stable")]
    levels = np.flatnonzero(np.diff(depth[by_depth])) + 1
    for group in np.split(by_depth, levels):            # deepest first
        np.add.at(carried, parent[group], carried[group])
    out = np.zeros(len(facets.owners))
    # the flux leaving `child` through the facet to its parent: its subtree's excess
    sign = np.where(facets.owners[facet_of_child, 0] == child, 1.0, -1.0)
    out[facet_of_child] = sign * carried[child]
    return out


def dual_bound(mesh: Mesh, space: Space, tensors: np.ndarray, cell_material: np.ndarray,
               axis: int, lo: np.ndarray, hi: np.ndarray, *, tol: float,
               facets: FacetTable | None = None) -> DualBound:
    """The lower bound of k_eff along `axis` (mesh axis order) from the CR/RT0 flux.

    Parameters
    ----------
    mesh : Mesh
    space : Space
        The P1 space of `mesh` (:func:`~._assembly.fe_space`), for the element geometry.
    tensors : (n_materials, d, d) ndarray
        Conductivities, mesh axis order.
    cell_material : (M,) ndarray of int
        Row of `tensors` per element.
    axis : int
        Mesh axis (0 = plane or row, last = column).
    lo, hi : (d,) ndarray
        The box.
    tol : float
        Relative residual of the CR solve (the bound holds whatever it is; a looser
        solve gives a lower, still valid, bound).
    facets : FacetTable, optional
        :func:`facet_table` of the mesh, reused across axes.

    Returns
    -------
    DualBound

    Raises
    ------
    ValueError
        A face of the axis with no facet on it. No flux crossing the box, or one lost to
        round-off (contrasts near 1e16), gives the certain lower bound 0.
    """
    d = mesh.ndim
    facets = facet_table(mesh.cells) if facets is None else facets
    low, high = _fixed_facets(space.points, facets, axis, lo, hi)
    if not low.size or not high.size:
        raise ValueError("a face of the box has no facet on it, so no flux can cross: "
                         "mesh the material on both faces.")
    fixed = np.concatenate([low, high])
    n = len(facets.owners)
    matrix = _cr_stiffness(space, facets, tensors, cell_material)
    # facet-connected parts without a fixed facet float (touching the rest at an edge or
    # a point at most): pin them; their flux is zero
    parts = connected_parts(matrix)
    anchored_part = np.zeros(parts.max() + 1, dtype=bool)
    anchored_part[parts[fixed]] = True
    _, pins = np.unique(parts, return_index=True)
    pins = pins[~anchored_part[parts[pins]]]
    held = np.concatenate([fixed, pins])
    w = np.zeros(n)
    w[high] = 1.0
    free, reduced, coupling = split_fixed(matrix, held)
    del matrix
    fixed_vertices = np.unique(facets.vertices[fixed])
    coarse = _cr_coarse(facets, len(space.points), free, fixed_vertices)
    solver = SPDSolver(reduced, tol=tol, overwrite=True, coarse=coarse)
    rhs = -(coupling @ w[~free])
    w[free], info = solver.solve(rhs)
    info = SolverInfo(info.unknowns, info.iterations, info.residual,
                      info.seconds + solver.setup_seconds, solver.setup_seconds)
    del solver, reduced, coupling, coarse

    cell_anchored = anchored_part[parts[facets.of_cell[:, 0]]]
    m = mesh.n_cells
    outward = np.empty((d + 1, m))             # facet fluxes out of each element
    vol = np.empty(m)

    def fill(part: slice) -> None:
        g, v = barycentric_gradients(space.points, space.cells[part])   # (d+1, d, m)
        vol[part] = np.abs(v)
        local = np.take(w, facets.of_cell[part].T)                      # (d+1, m)
        grad = -d * np.einsum("km,kjm->jm", local, g)                   # grad_h w
        flux = _apply(_tensor_rows(tensors, cell_material[part]), grad)
        # |F_k| n_k = -d |T| grad lambda_k: the flux out through facet k
        outward[:, part] = -d * np.abs(v) * _dot(g, flux[None])

    for _ in _map(fill, m):
        pass
    outward[:, ~cell_anchored] = 0.0

    # one flux per facet, out of its first owner: the mean of its two elements' views,
    # zero on the insulated boundary, free on the fixed faces
    owners = facets.owners
    rows = np.arange(m)
    corner_of = np.empty((n, 2), dtype=np.intp)
    corner_of.fill(-1)
    for k in range(d + 1):
        f = facets.of_cell[:, k]
        firsts = owners[f, 0] == rows
        corner_of[f[firsts], 0] = k
        corner_of[f[~firsts], 1] = k
    inner = ~facets.boundary
    facet_flux = np.zeros(n)
    one = outward[corner_of[:, 0], owners[:, 0]]
    facet_flux[inner] = 0.5 * (one[inner] - outward[corner_of[inner, 1], owners[inner, 1]])
    facet_flux[fixed] = one[fixed]
    # each element's net outflow, and its removal along the tree
    sign = np.where(owners[facets.of_cell, 0] == rows[:, None], 1.0, -1.0)   # (M, d+1)
    excess = (sign * facet_flux[facets.of_cell]).sum(axis=1)
    facet_flux -= _route_to_faces(excess, facets, fixed, cell_anchored)
    out_of_cell = sign * facet_flux[facets.of_cell]                           # (M, d+1)
    through = float(facet_flux[high].sum())
    back = float(-facet_flux[low].sum())
    if not through > 0 or abs(through - back) > ROUTE_TOLERANCE * through:
        # no flux crosses (no material connects the faces), or round-off beyond float64
        # (contrast 1e16): 0 is the one lower bound that is certain
        return DualBound(0.0, np.zeros((m, d)), float("inf"), info, n)
    imbalance = float(np.abs(excess).max(initial=0.0)) / through

    # the constant flux of each element with exactly those facet fluxes:
    # s = -sum_k (p_k - c) g_k / (d |T|), p_k the corner opposite facet k
    inverse = np.linalg.inv(tensors)
    s = np.empty((d, m))

    def rebuild(part: slice) -> float:
        corners = np.take(space.points, space.cells[part], axis=0)           # (m, d+1, d)
        corners -= corners.mean(axis=1, keepdims=True)
        s[:, part] = (-np.einsum("mk,mkj->jm", out_of_cell[part], corners)
                      / (d * vol[part]))
        sp = s[:, part]
        return float(np.sum(vol[part] * _dot(sp, _apply(
            _tensor_rows(inverse, cell_material[part]), sp))))

    energy = sum(_map(rebuild, m))
    if not energy > 0:
        return DualBound(0.0, np.zeros((m, d)), float("inf"), info, n)
    scale = through / energy                       # the optimal multiple of s
    q_lower = through * scale
    length = hi[axis] - lo[axis]
    area = float(np.prod(np.delete(hi - lo, axis)))
    return DualBound(float(q_lower * length / area), np.ascontiguousarray((scale * s).T),
                     imbalance, info, n)


def element_energies(space: Space, values: np.ndarray, tensors: np.ndarray,
                     cell_material: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per element: ``int_T grad u . C grad u`` (M,) and ``int_T grad u`` (M, d), exact
    for P1 and P2 (mesh axis order)."""
    lam, w = _quadrature(space.ndim, space.order)
    tensors = np.asarray(tensors, dtype=np.float64)
    m = len(space.cells)
    energy = np.empty(m)
    mean = np.empty((space.ndim, m))

    def fill(part: slice) -> None:
        grad, vol = _field_gradients(space, values, part, lam)       # (nq, d, m)
        flux = _apply(_tensor_rows(tensors, cell_material[part]), grad)
        energy[part] = (w @ _dot(grad, flux)) * vol
        mean[:, part] = np.einsum("q,qjm->jm", w, grad) * vol

    for _ in _map(fill, m):
        pass
    return energy, mean.T


def hypercircle(space: Space, values: np.ndarray, dual: np.ndarray, tensors: np.ndarray,
                cell_material: np.ndarray) -> np.ndarray:
    """(M,) ``int_T (s - C grad u) . C^-1 (s - C grad u)``: the gap per element.

    `values`: the primal potential (0/1 on the faces); `dual`: (M, d) the optimally scaled
    dual flux (:attr:`DualBound.flux`, mesh axis order). The sum over the elements is
    ``Q_upper - Q_lower`` (the Prager-Synge identity), each term non-negative.
    """
    energy, mean = element_energies(space, values, tensors, cell_material)
    vol = np.abs(barycentric_gradients(space.points, space.cells)[1])
    inverse = np.linalg.inv(np.asarray(tensors, dtype=np.float64))
    s = np.ascontiguousarray(dual.T)
    complementary = vol * _dot(s, _apply(_tensor_rows(inverse, cell_material), s))
    return np.maximum(complementary - 2 * np.einsum("mj,mj->m", dual, mean) + energy, 0.0)
