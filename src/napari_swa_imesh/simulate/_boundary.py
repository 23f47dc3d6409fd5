"""Steady diffusion with conditions on the named facet groups: Dirichlet, Neumann, Robin.

Solves ``-div(k grad u) = f`` (``f`` per material) with, on any boundary facet group of
the mesh (``xmin`` ... ``zmax``, ``exterior_<A>``; see :func:`~napari_swa_imesh.mesh.facet_groups`):

* Dirichlet ``u = g``;
* Neumann: an inward flux density ``q`` (``k du/dn = q`` with n the outward normal:
  positive ``q`` enters the material; 0 is insulated, the default everywhere);
* Robin: exchange with a surrounding value, ``-k du/dn = h (u - u_inf)`` (a film
  coefficient ``h``, as CalculiX's ``*FILM``).

The result holds the field, the flux per element and the net inflow through each group,
and is checked for conservation: sources plus inflow through every group must add up to
zero, or the solve did not converge and the result is refused.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..mesh import Mesh
from ._assembly import cell_fluxes, fe_space, p1_embedding, stiffness_matrix
from ._conductivity import conductivity_tensors, material_label
from ._fe import _skfem, fe_basis, vertex_values
from ._solve import SolverInfo, check_constrained, connected_parts, solve_dirichlet

__all__ = ["BoundaryResult", "solve_boundary_value"]

#: Relative imbalance of sources and boundary inflow above which a solve is refused.
BALANCE_TOLERANCE = 1e-6


@dataclass
class BoundaryResult:
    """The field of a boundary-value problem and what crossed each group.

    Attributes
    ----------
    potential : (N,) ndarray
        The field at the mesh vertices.
    flux : (M, d) ndarray
        ``-C grad u`` per element, components in x, y(, z) order.
    inflow : dict of str to float
        Net amount entering through each boundary group per unit time (negative: leaving),
        from the discrete balance (reactions), for every group with a condition and the
        insulated rest (0 within the solver's tolerance).
    source : float
        Total of the volume sources.
    solver : SolverInfo
    mesh : Mesh
    order : int
    dofs : int
    seconds : dict of str to float
    """

    potential: np.ndarray
    flux: np.ndarray
    inflow: dict[str, float]
    source: float
    solver: SolverInfo
    mesh: Mesh
    order: int
    dofs: int
    seconds: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict:
        """Plain-JSON summary (what ``swa-imesh simulate --json`` prints in this mode)."""
        return {"inflow": dict(self.inflow), "source": self.source,
                "potential_range": [float(self.potential.min()), float(self.potential.max())],
                "order": self.order, "dofs": self.dofs, "elements": self.mesh.n_cells,
                "iterations": self.solver.iterations, "residual": self.solver.residual,
                "seconds": dict(self.seconds)}

    def describe(self) -> str:
        lines = [f"steady diffusion with boundary conditions, P{self.order} on "
                 f"{self.mesh.n_cells} elements, {self.dofs} unknowns "
                 f"({self.solver.iterations} CG iterations, residual "
                 f"{self.solver.residual:.1e})",
                 f"field from {self.potential.min():.6g} to {self.potential.max():.6g}; "
                 f"sources {self.source:.6g}"]
        lines += [f"inflow through {name}: {value:.6g}" for name, value in self.inflow.items()]
        return "\n".join(lines)


def _facet_ids(fem_mesh, facets: np.ndarray) -> np.ndarray:
    """scikit-fem's facet index of each facet given by its (F, d) vertex ids."""
    ours = np.sort(facets, axis=1)
    theirs = np.sort(fem_mesh.facets.T, axis=1)
    both = np.concatenate([theirs, ours])
    _, inverse = np.unique(both, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    facet_of_class = np.full(inverse.max() + 1, -1, dtype=np.intp)
    facet_of_class[inverse[:len(theirs)]] = np.arange(len(theirs))
    found = facet_of_class[inverse[len(theirs):]]
    if (found < 0).any():
        raise ValueError("a facet group does not match the mesh's facets; the groups must "
                         "come from this mesh.")
    return found


def _per_group(values, groups: dict, kind: str, arity: int) -> dict[str, tuple]:
    """Check one kind of condition: known boundary group names and numbers."""
    out = {}
    for name, value in dict(values or {}).items():
        if name not in groups:
            known = ", ".join(n for n in groups if not n.startswith("interface_"))
            raise ValueError(f"{kind} condition on {name!r}: the mesh has no such boundary "
                             f"group; its boundary groups are {known}.")
        if name.startswith("interface_"):
            raise ValueError(f"{kind} condition on {name!r}: interfaces lie inside the mesh; "
                             "put conditions on boundary groups (box sides, exterior_<A>).")
        numbers = np.atleast_1d(np.asarray(value, dtype=float))
        if numbers.size != arity or not np.isfinite(numbers).all():
            what = "two numbers, h and u_inf" if arity == 2 else "one number"
            raise ValueError(f"{kind} condition on {name!r} needs {what}; got {value!r}.")
        if kind == "Robin" and numbers[0] <= 0:
            raise ValueError(f"Robin condition on {name!r}: the film coefficient h must be "
                             f"positive; got {numbers[0]:g}.")
        out[name] = tuple(float(v) for v in numbers)
    return out


def solve_boundary_value(mesh: Mesh, conductivity: Mapping, *, dirichlet=None,
                         neumann=None, robin=None, source=None, order: int = 1,
                         tol: float = 1e-10) -> BoundaryResult:
    """Steady diffusion on `mesh` with conditions on its named boundary facet groups.

    Parameters
    ----------
    mesh : Mesh
        Triangles or tetrahedra with a material per element.
    conductivity : mapping
        Per material, as for :func:`~napari_swa_imesh.simulate.simulate`.
    dirichlet : mapping of str to float, optional
        Group name -> fixed value.
    neumann : mapping of str to float, optional
        Group name -> inward flux density (amount per unit area and time; 0 insulates).
    robin : mapping of str to (float, float), optional
        Group name -> (film coefficient h > 0, surrounding value u_inf).
    source : mapping of int or str to float, optional
        Material -> volume source density ``f`` (amount per unit volume and time).
    order : {1, 2}
    tol : float
        Relative residual of the solve.

    Returns
    -------
    BoundaryResult

    Raises
    ------
    ValueError
        An unknown or interior group, a group with two conditions, no Dirichlet or Robin
        condition reaching some connected part (its level would be undetermined), or a
        solve whose sources and inflows do not balance.

    Examples
    --------
    A bar with u = 0 at xmin and an inward flux of 2 at xmax, k = 4: u = 2 x / 4.

    >>> from napari_swa_imesh.mesh import mesh_labels
    >>> r = solve_boundary_value(mesh_labels(np.ones((2, 6), np.uint8)), {1: 4.0},
    ...                          dirichlet={"xmin": 0.0}, neumann={"xmax": 2.0})
    >>> round(float(r.potential.max()), 9)
    3.0
    """
    from ..mesh import facet_groups

    skfem = _skfem()
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    groups = facet_groups(mesh)
    fixed_values = _per_group(dirichlet, groups, "Dirichlet", 1)
    fluxes = _per_group(neumann, groups, "Neumann", 1)
    films = _per_group(robin, groups, "Robin", 2)
    named = [*fixed_values, *fluxes, *films]
    twice = sorted({n for n in named if named.count(n) > 1})
    if twice:
        raise ValueError(f"{', '.join(twice)} carries more than one condition; give each "
                         "group one.")
    materials, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = conductivity_tensors(conductivity, materials, mesh.ndim, mesh.material_names)
    basis = fe_basis(mesh, order)                # facets and loads; same dof numbering
    space = fe_space(mesh, order)
    matrix = stiffness_matrix(space, tensors, cell_material)
    n = matrix.shape[0]
    rhs = np.zeros(n)
    total_source = 0.0
    if source:
        density = np.zeros(len(materials))
        for key, value in dict(source).items():
            label = material_label(key, mesh.material_names)
            hit = np.flatnonzero(materials == label)
            if not hit.size:
                raise ValueError(f"source for material {key!r}: the mesh has no such "
                                 f"material; it has {materials.tolist()}.")
            density[hit] = float(value)
        per_cell = density[cell_material]

        @skfem.LinearForm
        def load(v, w):
            return w["f"] * v

        rhs += skfem.asm(load, basis, f=np.ascontiguousarray(
            np.broadcast_to(per_cell[:, None], basis.dx.shape)))
        total_source = float(np.sum(per_cell[:, None] * basis.dx))

    ids = {}
    for name in named:
        facets = groups[name].facets
        assert facets is not None           # facet_groups gives them unless asked not to
        ids[name] = _facet_ids(basis.mesh, facets)
    facet_bases = {name: skfem.FacetBasis(basis.mesh, basis.elem, facets=ids[name],
                                          intorder=2 * order)
                   for name in [*fluxes, *films]}

    @skfem.LinearForm
    def unit(v, w):
        return v

    @skfem.BilinearForm
    def exchange(u, v, w):
        return u * v

    # int v over each group, once: the Neumann and Robin loads and the Neumann inflow
    surface = {name: skfem.asm(unit, fb) for name, fb in facet_bases.items()}
    for name, (q,) in fluxes.items():
        rhs += q * surface[name]
    robin_matrix = None
    for name, (h, u_inf) in films.items():
        part = h * skfem.asm(exchange, facet_bases[name]).tocsr()
        robin_matrix = part if robin_matrix is None else robin_matrix + part
        rhs += h * u_inf * surface[name]
    system = matrix if robin_matrix is None else (matrix + robin_matrix).tocsr()

    fixed_parts = [basis.get_dofs(facets=ids[name]).flatten() for name in fixed_values]
    fixed = np.concatenate(fixed_parts) if fixed_parts else np.zeros(0, dtype=np.intp)
    values = np.concatenate([np.full(len(dofs), fixed_values[name][0])
                             for name, dofs in zip(fixed_values, fixed_parts)]) \
        if fixed_parts else np.zeros(0)
    fixed, first = np.unique(fixed, return_index=True)       # shared edges of two groups
    values = values[first]
    anchors = fixed
    if films:
        anchors = np.concatenate([fixed, *[
            basis.get_dofs(facets=ids[name]).flatten() for name in films]])
    if not anchors.size:
        raise ValueError("no Dirichlet or Robin condition: the level of the field is "
                         "undetermined; fix a value (--dirichlet) or add an exchange "
                         "(--robin) on some group.")
    check_constrained(connected_parts(matrix), anchors, "the Dirichlet and Robin groups",
                      space.element_dofs, mesh.material)
    seconds["assemble"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    u, info = solve_dirichlet(system, fixed, values, rhs, tol=tol,
                              coarse=p1_embedding(space))
    seconds["solve"] = time.perf_counter() - t0

    # what enters through each group: the residual of the balance on its dofs
    # (the constant is in the stiffness' kernel, so these add up with the rest to 0)
    reaction = system @ u - rhs
    inflow: dict[str, float] = {}
    claimed = np.zeros(n, dtype=bool)
    for name, dofs in zip(fixed_values, fixed_parts):
        dofs = dofs[~claimed[dofs]]
        claimed[dofs] = True
        inflow[name] = float(reaction[dofs].sum())
    for name, (q,) in fluxes.items():
        inflow[name] = q * float(surface[name].sum())
    for name, (h, u_inf) in films.items():
        fb = facet_bases[name]
        inflow[name] = float(h * np.sum((u_inf - fb.interpolate(u)) * fb.dx))
    imbalance = total_source + sum(inflow.values())
    scale = max(abs(total_source), *[abs(v) for v in inflow.values()], 1e-300)
    if abs(imbalance) > BALANCE_TOLERANCE * scale:
        raise ValueError(f"sources ({total_source:.6g}) and inflow through the groups "
                         f"({sum(inflow.values()):.6g}) do not balance: the solve did not "
                         "converge far enough; lower --tol or the conductivity contrast.")
    flux = cell_fluxes(space, u, tensors, cell_material)[0]
    return BoundaryResult(vertex_values(u, len(mesh.points)),
                          np.ascontiguousarray(flux[:, ::-1]), inflow, total_source, info,
                          mesh, order, n, seconds)
