"""Transient diffusion: implicit Euler on the same assembly as the steady solve.

    c du/dt - div(k grad u) = 0,

``c`` the capacity per material (heat capacity rho*c_p, or porosity for a solute), ``k``
the conductivity. Implicit Euler is unconditionally stable and, with the consistent mass
matrix and insulated faces, conserves the total amount ``int c u`` to solver precision
(tested); each step solves ``(M / dt + K) u_new = M u_old / dt`` with one AMG hierarchy
built once for all steps.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from numbers import Real

import numpy as np

from ..mesh import Mesh
from ._assembly import fe_space, p1_embedding, stiffness_matrix
from ._conductivity import conductivity_tensors, material_label
from ._fe import fe_basis, mass_basis, mass_matrix, vertex_values
from ._protocols import face_dofs, face_names
from ._simulate import check_tolerance, prepare_mesh
from ._solve import DEFAULT_TOLERANCE, SPDSolver, solve_spd, split_fixed

__all__ = ["TransientResult", "simulate_transient", "transient_steps"]


@dataclass
class TransientResult:
    """A time series of the field.

    Attributes
    ----------
    times : (T,) ndarray
        Saved times, 0 first.
    values : (T, N) ndarray
        The field at the mesh vertices at each saved time.
    amount : dict of int to (T,) ndarray
        ``int c u`` over each material at each saved time.
    mesh : Mesh
    order : int
    dofs : int
    iterations : (steps,) ndarray of int
        Conjugate-gradient iterations per step.
    seconds : dict of str to float
    """

    times: np.ndarray
    values: np.ndarray
    amount: dict[int, np.ndarray]
    mesh: Mesh
    order: int
    dofs: int
    iterations: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict:
        """Plain-JSON summary."""
        return {
            "times": self.times.tolist(),
            "amount": {str(m): a.tolist() for m, a in self.amount.items()},
            "order": self.order, "dofs": self.dofs, "elements": self.mesh.n_cells,
            "iterations": int(self.iterations.sum()),
            "seconds": dict(self.seconds),
        }

    def describe(self) -> str:
        """Two lines for people: the run's size and cost, the amount at start and end."""
        total = sum(a for a in self.amount.values())
        lines = [f"transient diffusion, P{self.order} on {self.mesh.n_cells} elements, "
                 f"{self.dofs} unknowns, {self.iterations.size} implicit Euler steps to "
                 f"t = {self.times[-1]:g} ({int(self.iterations.sum())} CG iterations)",
                 f"total amount {total[0]:.6g} at t = 0, {total[-1]:.6g} at the end"]
        return "\n".join(lines)


def _per_material(value, materials, names: Mapping[int, str], what: str,
                  default: float) -> np.ndarray:
    """A number, or a {material label or name: number} mapping with `default` for the
    materials it leaves out, as one value per material."""
    if isinstance(value, Mapping):
        table: dict[int, float] = {}
        for key, number in value.items():
            label = material_label(key, names)
            if label is None or label not in set(int(m) for m in materials):
                raise ValueError(f"{what} names material {key!r}, which is not in the mesh; "
                                 f"the materials are {', '.join(map(str, materials))}.")
            table[label] = _number(number, f"the {what} of material {key}")
        return np.array([table.get(int(m), default) for m in materials], dtype=np.float64)
    return np.full(len(materials), _number(value, f"the {what}"), dtype=np.float64)


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not np.isfinite(value):
        raise ValueError(f"{what} must be a finite number, not {value!r}.")
    return float(value)


def _whole(value, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{what} must be a positive whole number, not {value!r}.")
    return int(value)


def transient_steps(mesh_or_labels, conductivity: Mapping, *, duration: float, steps: int,
                    capacity=1.0, initial=0.0, fixed: Mapping[str, float] | None = None,
                    spacing=None, order: int = 1, exclude=(), save_every: int = 1,
                    material_names: Mapping[int, str] | None = None,
                    tol: float = DEFAULT_TOLERANCE):
    """Run :func:`simulate_transient` step by step, for a progress bar.

    Parameters
    ----------
    mesh_or_labels, conductivity, duration, steps, capacity, initial, fixed, spacing, \
order, exclude, save_every, material_names, tol
        As for :func:`simulate_transient`.

    Yields
    ------
    (done, total, message) : (int, int, str)
        Progress: assembly, then one report per time step.

    Returns
    -------
    TransientResult
        As the generator's return value (``StopIteration.value``).
    """
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2 (P1 or P2 elements), not {order!r}.")
    duration = _number(duration, "duration")
    if duration <= 0:
        raise ValueError(f"duration must be a positive time, not {duration!r}.")
    steps = _whole(steps, "steps")
    save_every = _whole(save_every, "save_every")
    check_tolerance(tol)
    fixed = dict(fixed or {})
    t0 = time.perf_counter()
    mesh = prepare_mesh(mesh_or_labels, spacing=spacing, exclude=exclude,
                        material_names=material_names)
    for face, value in fixed.items():
        if face not in face_names(mesh.ndim):
            raise ValueError(f"unknown face {face!r}; the faces of a {mesh.ndim}-D box are "
                             f"{', '.join(face_names(mesh.ndim))}.")
        _number(value, f"the value fixed on {face}")
    materials, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = conductivity_tensors(conductivity, materials, mesh.ndim, mesh.material_names)
    cap = _per_material(capacity, materials, mesh.material_names, "capacity", 1.0)
    if np.any(cap <= 0):
        raise ValueError("capacity must be positive for every material.")
    start = _per_material(initial, materials, mesh.material_names, "initial value", 0.0)
    yield 1, steps + 2, f"assembling P{order} on {mesh.n_cells} elements"

    basis = fe_basis(mesh, order)                # mass and loads; same dof numbering
    space = fe_space(mesh, order)
    stiffness = stiffness_matrix(space, tensors, cell_material)
    exact = mass_basis(basis)                  # mass, start and amounts share it
    mass = mass_matrix(exact, cap[cell_material])
    dt = duration / steps
    # the mass term keeps the system definite: a part with no fixed face is well posed
    system = (mass / dt + stiffness).tocsr()
    lo, hi = mesh.image_box()
    fixed_dofs = []
    for face in fixed:
        dofs_on_face = face_dofs(basis.doflocs, lo, hi, face)
        if dofs_on_face.size == 0:
            raise ValueError(f"no meshed material touches the {face} face, so a value fixed "
                             "there acts on nothing; fix another face or mesh the material "
                             "on it.")
        fixed_dofs.append(dofs_on_face)
    dofs = np.concatenate(fixed_dofs) if fixed_dofs else np.zeros(0, dtype=np.intp)
    values = np.concatenate([np.full(d.size, float(fixed[f]))
                             for f, d in zip(fixed, fixed_dofs)]) if fixed_dofs else np.zeros(0)
    free, reduced, coupling = split_fixed(system, dofs)
    coarse = p1_embedding(space)             # P2: the P1 functions, first coarse level
    if coarse is not None:
        coarse = coarse[free][:, free[:coarse.shape[1]]]
    solver = SPDSolver(reduced, tol=tol, overwrite=True, coarse=coarse)
    seconds = {"mesh_and_assembly": time.perf_counter() - t0}

    u = _initial_field(exact, order, mass, (cap * start)[cell_material])
    u[dofs] = values
    fixed_values = u[~free].copy()
    cell_amount = _amount_per_cell_fn(exact, cap[cell_material])

    times, saved, amounts, iterations = [0.0], [vertex_values(u, len(mesh.points))], \
        [cell_amount(u)], []
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        yield k + 1, steps + 2, f"step {k} of {steps}"
        b = (mass @ u)[free] / dt - coupling @ fixed_values
        u_free, info = solver.solve(b, u[free])
        u[free] = u_free
        iterations.append(info.iterations)
        if k % save_every == 0 or k == steps:
            times.append(k * dt)
            saved.append(vertex_values(u, len(mesh.points)))
            amounts.append(cell_amount(u))
    seconds["steps"] = time.perf_counter() - t0
    yield steps + 2, steps + 2, "done"
    per_cell = np.stack(amounts)                                      # (T, M)
    amount = {int(m): per_cell[:, cell_material == i].sum(axis=1)
              for i, m in enumerate(materials)}
    return TransientResult(np.array(times), np.stack(saved), amount, mesh, order,
                           int(system.shape[0]), np.array(iterations, dtype=int), seconds)


def _initial_field(exact, order: int, mass, load_per_cell: np.ndarray) -> np.ndarray:
    """The start as a finite-element field that keeps its amount ``int c u`` exactly.

    P1: the lumped (row-sum) projection, a weighted average of the neighbouring elements'
    values, so a 0/1 start stays within [0, 1]. P2: the consistent L2 projection (lumped
    P2 mass has non-positive vertex entries); its overshoot is small.
    """
    if not np.any(load_per_cell):
        return np.zeros(mass.shape[0])
    rhs = _cell_load(exact, load_per_cell)
    if order == 1:
        return rhs / np.asarray(mass.sum(axis=1)).ravel()
    return solve_spd(mass, rhs, tol=1e-12)[0]


def _cell_load(exact, per_cell: np.ndarray) -> np.ndarray:
    """``b_i = int c_e phi_i`` for a piecewise-constant c, on a :func:`mass_basis`."""
    import skfem

    field = np.broadcast_to(per_cell[:, None], (per_cell.size, exact.X.shape[-1]))

    @skfem.LinearForm
    def form(v, w):
        return w["c"] * v
    return skfem.asm(form, exact, c=np.ascontiguousarray(field))


def _amount_per_cell_fn(exact, capacity_per_cell: np.ndarray):
    """A function u -> (M,) ``int_e c u`` on a :func:`mass_basis` (exact for P1 and P2)."""
    weights = exact.dx                                               # (M, nqp)

    def amount(u: np.ndarray) -> np.ndarray:
        return capacity_per_cell * np.sum(np.asarray(exact.interpolate(u)) * weights, axis=1)
    return amount


def simulate_transient(mesh_or_labels, conductivity: Mapping, *, duration: float,
                       steps: int, capacity=1.0, initial=0.0,
                       fixed: Mapping[str, float] | None = None, spacing=None,
                       order: int = 1, exclude=(), save_every: int = 1,
                       material_names: Mapping[int, str] | None = None,
                       tol: float = DEFAULT_TOLERANCE) -> TransientResult:
    """Transient diffusion on the mesh by implicit Euler.

    Parameters
    ----------
    mesh_or_labels : Mesh or (M, N[, P]) array_like of int
    conductivity : mapping
        As for :func:`simulate`.
    duration : float
        End time (the units of ``capacity * length^2 / conductivity``).
    steps : int
        Implicit Euler steps of ``duration / steps`` each.
    capacity : float or mapping of int or str to float
        ``c`` per material, by label or name (default 1; materials a mapping leaves out
        get 1).
    initial : float or mapping of int or str to float
        Initial value per material (a released substance: 1 in the source material; a
        mapping leaves the others at 0); projected onto the elements so that its amount
        is kept.
    fixed : mapping of str to float, optional
        Faces of the box with a fixed value, e.g. ``{"xmin": 1.0}`` for a heat front
        entering from x = min; every other face is insulated. Faces: ``xmin`` ...
        ``zmax`` (x = column, y = row, z = plane).
    spacing, order, exclude, material_names, tol
        As for :func:`simulate`.
    save_every : int
        Keep every k-th step (and the last).

    Returns
    -------
    TransientResult

    Examples
    --------
    A front entering a uniform bar: after a long time the bar takes the face value.

    >>> import numpy as np
    >>> labels = np.ones((2, 8), dtype=np.uint8); labels[0, 0] = 2
    >>> r = simulate_transient(labels, {1: 1.0, 2: 1.0}, duration=500.0, steps=20,
    ...                        fixed={"xmin": 1.0})
    >>> bool(np.allclose(r.values[-1], 1.0, atol=1e-3))
    True
    """
    gen = transient_steps(mesh_or_labels, conductivity, duration=duration, steps=steps,
                          capacity=capacity, initial=initial, fixed=fixed, spacing=spacing,
                          order=order, exclude=exclude, save_every=save_every,
                          material_names=material_names, tol=tol)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value
