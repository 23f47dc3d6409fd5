"""Transient diffusion with error control, on the same assembly as the steady solve.

    c du/dt - div(k grad u) = 0,

``c`` the capacity per material (heat capacity rho*c_p, or porosity for a solute), ``k``
the conductivity. The run is asked an accuracy, ``error`` (default 1 % of the largest jump
of the data: fixed values and initial values), and chooses its resolution for it:

* **space** (:mod:`._transient_space`): a label image is meshed so that elements near the
  fixed faces and the jumps of the initial value resolve the diffusion length
  ``sqrt(D t)`` of the earliest saved time (the IMESH octree alone coarsens a uniform
  material to a handful of elements: 18 vertices for a 8 x 64 slab, 0.09 max error);
* **time** (:mod:`._time_steps`): implicit Euler with step doubling and Richardson
  extrapolation, dyadic steps that start short at t = 0 and grow as the field smooths;
* **estimate**: at the saved times, the space error by the P2 elliptic reconstruction
  and the time error as the sum of the step estimates; printed, in the summary, and a
  sentence when it exceeds what was asked.

Each implicit Euler solve with the consistent mass matrix and insulated faces conserves
the total amount ``int c u`` to solver precision, and so does the extrapolation (tested).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from numbers import Real

import numpy as np

from .._steps import run_steps
from ..mesh import Mesh
from ._assembly import fe_space, p1_embedding, stiffness_matrix
from ._conductivity import conductivity_tensors, material_label
from ._fe import fe_basis, mass_basis, mass_matrix, vertex_values
from ._protocols import face_dofs, face_names
from ._simulate import check_tolerance, prepare_mesh
from ._solve import DEFAULT_TOLERANCE, solve_spd
from ._time_steps import adaptive_euler
from ._transient_error import (
    DEFAULT_ERROR,
    POSTERIORI_ROUNDS,
    SPACE_SHARE,
    ErrorEstimate,
    _edge_count,
    _error_warnings,
    _estimate_indices,
    _refine_by_estimate,
    _worth_refining,
)
from ._transient_space import ESTIMATE_UNKNOWNS, SpaceEstimator, resolve_fronts

__all__ = ["DEFAULT_ERROR", "ErrorEstimate", "TransientResult", "simulate_transient",
           "transient_steps"]


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
    iterations : (T - 1,) ndarray of int
        Conjugate-gradient iterations between consecutive saved times.
    seconds : dict of str to float
    error : ErrorEstimate or None
    warnings : list of str
        One sentence per way the run may miss the asked error.
    """

    times: np.ndarray
    values: np.ndarray
    amount: dict[int, np.ndarray]
    mesh: Mesh
    order: int
    dofs: int
    iterations: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)
    error: ErrorEstimate | None = None
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        """Plain-JSON summary."""
        out = {
            "times": self.times.tolist(),
            "amount": {str(m): a.tolist() for m, a in self.amount.items()},
            "order": self.order, "dofs": self.dofs, "elements": self.mesh.n_cells,
            "vertices": len(self.mesh.points),
            "iterations": int(self.iterations.sum()),
            "seconds": dict(self.seconds),
            "warnings": list(self.warnings),
        }
        if self.error is not None:
            out["error"] = self.error.summary()
        return out

    def describe(self) -> str:
        """The run's size and cost, the amount at start and end, the error estimate, one
        line each (the warnings are raised as ``UserWarning`` and kept in `warnings`)."""
        total = sum(a for a in self.amount.values())
        steps = self.error.steps if self.error is not None else self.iterations.size
        lines = [f"transient diffusion, P{self.order} on {self.mesh.n_cells} elements, "
                 f"{self.dofs} unknowns, {steps} implicit Euler steps to "
                 f"t = {self.times[-1]:g} ({int(self.iterations.sum())} CG iterations)",
                 f"total amount {total[0]:.6g} at t = 0, {total[-1]:.6g} at the end"]
        if self.error is not None:
            lines.append(self.error.describe())
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
                    tol: float = DEFAULT_TOLERANCE, error: float | None = DEFAULT_ERROR):
    """Run :func:`simulate_transient` step by step, for a progress bar.

    Parameters
    ----------
    mesh_or_labels, conductivity, duration, steps, capacity, initial, fixed, spacing, \
order, exclude, save_every, material_names, tol, error
        As for :func:`simulate_transient`.

    Yields
    ------
    (done, total, message) : (int, int, str)
        Progress: assembly, then one report per saved time.

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
    if error is not None:
        error = _number(error, "error")
        if not 0 < error < 1:
            raise ValueError(f"error must lie between 0 and 1 (a share of the largest "
                             f"jump of the data, e.g. 0.01), not {error!r}.")
    fixed = dict(fixed or {})
    t0 = time.perf_counter()
    ndim = (mesh_or_labels.ndim if isinstance(mesh_or_labels, Mesh)
            else np.ndim(mesh_or_labels))
    for face, value in fixed.items():
        if face not in face_names(ndim):
            raise ValueError(f"unknown face {face!r}; the faces of a {ndim}-D box are "
                             f"{', '.join(face_names(ndim))}.")
        _number(value, f"the value fixed on {face}")
    saves = [k for k in range(save_every, steps + 1, save_every)]
    if not saves or saves[-1] != steps:
        saves.append(steps)
    base = duration / steps
    plan = None
    if isinstance(mesh_or_labels, Mesh) or error is None:
        mesh = prepare_mesh(mesh_or_labels, spacing=spacing, exclude=exclude,
                            material_names=material_names)
    else:
        plan = _front_plan(mesh_or_labels, conductivity, capacity, initial, fixed,
                           spacing=spacing, exclude=exclude, names=material_names,
                           first=saves[0] * base, duration=duration)
        mesh, sized = resolve_fronts(mesh_or_labels, spacing=spacing, exclude=exclude,
                                     material_names=material_names, faces=list(fixed),
                                     start_labels=plan["start_labels"],
                                     first=plan["first"], last=plan["last"],
                                     error=SPACE_SHARE * error)
        plan.update(sized)
    refinements = 0
    seconds: dict[str, float] = {}
    while True:
        materials, cell_material = np.unique(mesh.material, return_inverse=True)
        tensors = conductivity_tensors(conductivity, materials, mesh.ndim, mesh.material_names)
        cap = _per_material(capacity, materials, mesh.material_names, "capacity", 1.0)
        if np.any(cap <= 0):
            raise ValueError("capacity must be positive for every material.")
        start = _per_material(initial, materials, mesh.material_names, "initial value", 0.0)
        total = len(saves) + 2
        yield 1, total, f"assembling P{order} on {mesh.n_cells} elements"

        basis = fe_basis(mesh, order)                # mass and loads; same dof numbering
        space = fe_space(mesh, order)
        stiffness = stiffness_matrix(space, tensors, cell_material)
        exact = mass_basis(basis)                  # mass, start and amounts share it
        mass = mass_matrix(exact, cap[cell_material])
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
        free = np.ones(mass.shape[0], dtype=bool)
        free[dofs] = False
        coarse = p1_embedding(space)             # P2: the P1 functions, first coarse level
        if coarse is not None:
            coarse = coarse[free][:, free[:coarse.shape[1]]]
        data = np.concatenate([values, start])
        jump = float(data.max() - data.min()) if data.size else 0.0
        u = _initial_field(exact, order, mass, (cap * start)[cell_material])
        u[dofs] = values
        cell_amount = _amount_per_cell_fn(exact, cap[cell_material])
        estimator, notes = None, []
        if order == 1 and jump > 0:
            unknowns = len(mesh.points) + _edge_count(mesh)
            if unknowns <= ESTIMATE_UNKNOWNS:
                estimator = SpaceEstimator(mesh, tensors, cell_material, cap[cell_material],
                                           fixed, tol, mass, stiffness, free)
            else:
                notes.append(f"the space error was not estimated: its P2 reconstruction "
                                f"would take {unknowns} unknowns (more than "
                                f"{ESTIMATE_UNKNOWNS}); check the result on a coarser image.")
        estimate_at = set(_estimate_indices(len(saves)))
        seconds["mesh_and_assembly"] = (seconds.get("mesh_and_assembly", 0.0)
                                        + time.perf_counter() - t0)

        times, saved, amounts = [0.0], [vertex_values(u, len(mesh.points))], [cell_amount(u)]
        space_error, time_error, iterations = [0.0], [0.0], []
        t0 = time.perf_counter()
        t_estimate = 0.0
        record = None
        run = adaptive_euler(mass, stiffness, u, free, base=base, saves=saves,
                             duration=duration,
                             tol=0.0 if error is None else (1 - SPACE_SHARE) * error * jump,
                             solver_tol=tol, coarse=coarse)
        for i, record in enumerate(run):
            yield i + 2, total, f"t = {record.time:g} of {duration:g} ({record.steps} steps)"
            times.append(record.time)
            saved.append(vertex_values(record.values, len(mesh.points)))
            amounts.append(cell_amount(record.values))
            time_error.append(record.time_error)
            iterations.append(record.iterations - sum(iterations))
            if estimator is not None and i in estimate_at:
                t1 = time.perf_counter()
                value, difference = estimator.error(record.values)
                if value >= np.nanmax(space_error):
                    estimator.worst = difference      # where to refine, if asked to
                space_error.append(value)
                t_estimate += time.perf_counter() - t1
            else:
                space_error.append(np.nan if jump > 0 else 0.0)
        seconds["steps"] = seconds.get("steps", 0.0) + time.perf_counter() - t0 - t_estimate
        seconds["error_estimate"] = seconds.get("error_estimate", 0.0) + t_estimate
        per_cell = np.stack(amounts)                                      # (T, M)
        amount = {int(m): per_cell[:, cell_material == i].sum(axis=1)
                  for i, m in enumerate(materials)}
        estimate = ErrorEstimate(np.array(space_error), np.array(time_error), jump, error,
                                 record.steps, record.rejected)
        if not _worth_refining(estimate, plan, estimator, error):
            break
        if refinements >= POSTERIORI_ROUNDS:
            plan.update(met=False, reason=f"{refinements} remeshings by the estimate, the "
                                          "most")
            break
        refined, why = _refine_by_estimate(mesh_or_labels, mesh, estimator,
                                           0.5 * SPACE_SHARE * error * jump,
                                           plan.get("tree"))
        if refined is None:
            plan.update(met=False, reason=why)
            break
        mesh, plan["tree"] = refined
        refinements += 1
        t0 = time.perf_counter()
    yield total, total, "done"
    estimate.refined = refinements
    notes += _error_warnings(estimate, plan, record, order, isinstance(mesh_or_labels, Mesh))
    for note in notes:
        warnings.warn(note, UserWarning, stacklevel=3)
    return TransientResult(np.array(times), np.stack(saved), amount, mesh, order,
                           int(mass.shape[0]), np.array(iterations, dtype=int), seconds,
                           estimate, notes)


def _front_plan(labels, conductivity, capacity, initial, fixed, *, spacing, exclude, names,
                first: float, duration: float) -> dict:
    """Diffusion lengths of the saved times and the initial value per voxel, from the
    labels (before meshing: they choose the mesh)."""
    lab = np.asarray(labels)
    names = dict(names or {})
    materials = np.setdiff1d(np.unique(lab), np.asarray(tuple(exclude), dtype=lab.dtype))
    if materials.size == 0:
        return {"start_labels": None, "first": 1.0, "last": 1.0}
    tensors = conductivity_tensors(conductivity, materials, lab.ndim, names)
    cap = _per_material(capacity, materials, names, "capacity", 1.0)
    if np.any(cap <= 0):
        raise ValueError("capacity must be positive for every material.")
    start = _per_material(initial, materials, names, "initial value", 0.0)
    eig = np.linalg.eigvalsh(np.asarray(tensors, dtype=float))        # (m, d)
    d_min = float(np.min(eig[:, 0] / cap))
    d_max = float(np.max(eig[:, -1] / cap))
    if d_min <= 0:
        d_min = d_max
    start_labels = None
    if np.ptp(start) > 0:
        table = np.full(int(lab.max()) + 1, np.nan)
        table[materials] = start
        start_labels = table[lab]
    return {"start_labels": start_labels, "first": float(np.sqrt(d_min * first)),
            "last": float(np.sqrt(d_max * duration))}


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
                       tol: float = DEFAULT_TOLERANCE,
                       error: float | None = DEFAULT_ERROR) -> TransientResult:
    """Transient diffusion with a mesh and time steps chosen for an asked error.

    Parameters
    ----------
    mesh_or_labels : Mesh or (M, N[, P]) array_like of int
    conductivity : mapping
        As for :func:`simulate`.
    duration : float
        End time (the units of ``capacity * length^2 / conductivity``).
    steps : int
        Saved times ``k * duration / steps``; the time steps adapt within them (with
        ``error=None``: implicit Euler steps of ``duration / steps`` each).
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
        Keep every k-th of those times (and the last).
    error : float or None
        Asked max error, as a share of the largest jump of the data (fixed values and
        initial values; default 0.01). A label image is meshed so that elements near
        fixed faces and jumps of the initial value resolve the earliest saved time's
        diffusion length, and the time steps adapt (implicit Euler with step doubling
        and extrapolation). The estimate is ``result.error``; a sentence in
        ``result.warnings`` says when it exceeds `error`. None: the mesh as the labels
        give it and fixed implicit Euler steps (estimated all the same).

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
                          material_names=material_names, tol=tol, error=error)
    return run_steps(gen)
