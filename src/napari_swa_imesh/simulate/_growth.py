"""Reaction-diffusion on the mesh: tumour growth (Fisher-KPP) and drug delivery.

    Fisher-KPP:  dc/dt = div(D grad c) + rho c (1 - c) - k(t) c
    drug:        dc/dt = div(D grad c) - lambda c - k(t) c + s

``D`` per material; a material with ``D = 0`` (CSF, outside the brain) is left out of
the mesh, so its boundary is insulated (no flux). The tumour starts as ``c = 1`` in a
seed ball; ``k(t)`` is a kill rate over time windows (chemotherapy cycles); the drug
enters through fixed values (on a box face or a whole material, e.g. a vessel) and
fluxes (on a box face) and volume sources per material.

Numerics: P1 elements with the lumped mass (:mod:`._growth_steps`: linearly implicit
steps that keep ``c`` within ``[0, 1]``, step doubling for the time error, Richardson
extrapolation), the elements the front can reach bounded by its width ``sqrt(D / rho)``
(:mod:`._growth_space`), and the total amount's balance reported term by term.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from .._steps import run_steps
from ..mesh import Mesh, signed_volumes
from ._assembly import fe_space, stiffness_matrix
from ._conductivity import material_label
from ._growth_space import FRONT_CELLS, REACH_MARGIN, bound_sizes, front_mesh, size_ratio
from ._growth_steps import BALANCE_TERMS, Reaction, imex_steps
from ._protocols import face_dofs, face_names
from ._transient import _number, _whole

__all__ = ["GROWTH_MODELS", "GrowthResult", "growth_steps", "simulate_growth"]

#: The reaction-diffusion models.
GROWTH_MODELS = ("fisher-kpp", "drug")
#: Default asked local error per step (a share of the field's scale).
DEFAULT_GROWTH_ERROR = 1e-3


@dataclass
class GrowthResult:
    """A reaction-diffusion time series.

    Attributes
    ----------
    times : (T,) ndarray
    values : (T, N) ndarray
        ``c`` at the mesh vertices at each saved time.
    mesh : Mesh
    model : str
    diffusivity : dict of int to float
        Per meshed material.
    seed : (centre, radius) or None
        The seed ball, centre in mesh (array-order) coordinates.
    amount : (T,) ndarray
        Total amount ``sum m c`` (lumped mass) at each saved time.
    balance : dict of str to (T,) ndarray
        Each term of the balance summed from t = 0 (growth, kill, decay, sources,
        boundary inflow, clipping).
    steps, rejected : int
    seconds : dict of str to float
    size : dict
        What the mesh sizing did (``max_ratio`` of element side to its bound, ...).
    warnings : list of str
    """

    times: np.ndarray
    values: np.ndarray
    mesh: Mesh
    model: str
    diffusivity: dict[int, float]
    seed: tuple[np.ndarray, float] | None
    amount: np.ndarray
    balance: dict[str, np.ndarray]
    steps: int
    rejected: int
    seconds: dict[str, float] = field(default_factory=dict)
    size: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    error = None                   # write_series looks for a transient error estimate

    @property
    def balance_residual(self) -> np.ndarray:
        """(T,) change of the amount minus the sum of the balance terms."""
        terms = sum(self.balance[t] for t in BALANCE_TERMS)
        return (self.amount - self.amount[0]) - terms

    def summary(self) -> dict:
        """Plain-JSON summary."""
        scale = max(float(np.max(np.abs(self.amount))), 1e-300)
        return {"model": self.model, "times": self.times.tolist(),
                "amount": self.amount.tolist(),
                "balance": {k: v.tolist() for k, v in self.balance.items()},
                "balance_residual": float(np.max(np.abs(self.balance_residual))) / scale,
                "elements": self.mesh.n_cells, "vertices": len(self.mesh.points),
                "steps": self.steps, "rejected": self.rejected,
                "max_size_ratio": float(self.size.get("max_ratio", 0.0)),
                "seconds": dict(self.seconds), "warnings": list(self.warnings)}

    def describe(self) -> str:
        """The run's size and cost, the amount and its balance, one line each."""
        end = {k: float(v[-1]) for k, v in self.balance.items() if v[-1] != 0}
        scale = max(float(np.max(np.abs(self.amount))), 1e-300)
        residual = float(np.max(np.abs(self.balance_residual))) / scale
        terms = ", ".join(f"{k} {v:+.6g}" for k, v in end.items()) or "no terms"
        return "\n".join([
            f"{self.model} on {self.mesh.n_cells} elements ({len(self.mesh.points)} "
            f"vertices), {self.steps} steps ({self.rejected} rejected) to "
            f"t = {self.times[-1]:g}",
            f"amount {self.amount[0]:.6g} at t = 0, {self.amount[-1]:.6g} at the end: "
            f"{terms}; balance residual {residual:.1e} of the amount"])


def _materials_table(value, names: Mapping[int, str], what: str) -> dict[int, float]:
    if not isinstance(value, Mapping) or not value:
        raise TypeError(f"{what} must be a mapping of material (label or name) to a number, "
                        f"such as {{2: 0.1, 3: 0.02}}, not {value!r}.")
    out = {}
    for key, number in value.items():
        label = material_label(key, names)
        if label is None:
            raise ValueError(f"{what} names material {key!r}, which is neither a label nor "
                             f"a material name.")
        number = _number(number, f"the {what} of material {key}")
        if number < 0:
            raise ValueError(f"the {what} of material {key} must not be negative, not "
                             f"{number:g}.")
        out[label] = number
    return out


def _check_kill(kill) -> tuple[tuple[float, float, float], ...]:
    out = []
    for window in kill or ():
        try:
            a, b, r = (float(x) for x in window)
        except (TypeError, ValueError):
            raise ValueError(f"a kill window is (start, end, rate), not {window!r}.") from None
        if not (np.isfinite([a, b, r]).all() and 0 <= a < b and r >= 0):
            raise ValueError(f"a kill window needs 0 <= start < end and a rate >= 0, not "
                             f"{window!r}.")
        out.append((a, b, r))
    return tuple(out)


def _seed_in_mesh(centre, world: np.ndarray | None, ndim: int) -> np.ndarray:
    """The seed centre, given in the files' x, y(, z), in mesh (array-order) coordinates."""
    c = np.asarray(centre, dtype=float)
    if world is None:
        return c[::-1].copy()
    return np.linalg.solve(world[:ndim, :ndim], c - world[:ndim, ndim])


def _boundary_loads(mesh: Mesh, flux: Mapping[str, float]) -> np.ndarray:
    """(N,) ``int_face q phi_i`` for an inward flux density q per box face (lumped)."""
    d = mesh.ndim
    out = np.zeros(len(mesh.points))
    if not flux:
        return out
    cells = np.sort(mesh.cells, axis=1)
    facets = np.concatenate([np.delete(cells, k, axis=1) for k in range(d + 1)])
    unique, counts = np.unique(facets, axis=0, return_counts=True)
    outer = unique[counts == 1]                                    # (F, d) boundary facets
    lo, hi = mesh.image_box()
    for face, q in flux.items():
        on = np.zeros(len(mesh.points), dtype=bool)
        on[face_dofs(mesh.points.T, lo, hi, face)] = True
        group = outer[on[outer].all(axis=1)]
        if group.size == 0:
            raise ValueError(f"no meshed material touches the {face} face, so a flux there "
                             "acts on nothing; give another face.")
        corners = mesh.points[group]                               # (F, d, d)
        edges = corners[:, 1:] - corners[:, :1]
        if d == 2:
            area = np.linalg.norm(edges[:, 0], axis=1)
        else:
            area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
        np.add.at(out, group.ravel(), np.repeat(q * area / d, d))
    return out


def growth_steps(mesh_or_labels, diffusivity: Mapping, *, duration: float,
                 model: str = "fisher-kpp", rate: float = 0.0, seed=None,
                 decay: float = 0.0, kill=(), fixed: Mapping | None = None,
                 flux: Mapping[str, float] | None = None, source: Mapping | None = None,
                 saves: int = 20, spacing=None, exclude=(),
                 material_names: Mapping[int, str] | None = None,
                 error: float = DEFAULT_GROWTH_ERROR, front_cells: float = FRONT_CELLS):
    """Run :func:`simulate_growth` step by step, for a progress bar.

    Parameters
    ----------
    mesh_or_labels, diffusivity, duration, model, rate, seed, decay, kill, fixed, flux, \
source, saves, spacing, exclude, material_names, error, front_cells
        As for :func:`simulate_growth`.

    Yields
    ------
    (done, total, message) : (int, int, str)
        Progress: meshing, then one report per accepted step (``done`` counts the saved
        times reached).

    Returns
    -------
    GrowthResult
        As the generator's return value (``StopIteration.value``).
    """
    t_start = time.perf_counter()
    if model not in GROWTH_MODELS:
        raise ValueError(f"model must be one of {', '.join(GROWTH_MODELS)}, not {model!r}.")
    duration = _number(duration, "duration")
    if duration <= 0:
        raise ValueError(f"duration must be a positive time, not {duration!r}.")
    saves = _whole(saves, "saves")
    error = _number(error, "error")
    if not 0 < error < 1:
        raise ValueError(f"error must lie between 0 and 1 (a share of the field's scale, "
                         f"e.g. 1e-3), not {error!r}.")
    front_cells = _number(front_cells, "front_cells")
    if front_cells < 1:
        raise ValueError(f"front_cells must be at least 1, not {front_cells!r}.")
    rate, decay = _number(rate, "rate"), _number(decay, "decay")
    kill = _check_kill(kill)
    is_mesh = isinstance(mesh_or_labels, Mesh)
    ndim = mesh_or_labels.ndim if is_mesh else np.ndim(mesh_or_labels)
    names = dict(material_names or {})
    if is_mesh:
        names = {**mesh_or_labels.material_names, **names}
    table = _materials_table(diffusivity, names, "diffusivity")
    fixed, flux = dict(fixed or {}), dict(flux or {})
    fixed_faces = {k: _number(v, f"the value fixed on {k}") for k, v in fixed.items()
                   if isinstance(k, str) and k in face_names(ndim)}
    fixed_materials: dict[int, float] = {}
    for key, value in fixed.items():
        if key in fixed_faces:
            continue
        label = material_label(key, names)
        if label is None:
            raise ValueError(f"fixed takes box faces ({', '.join(face_names(ndim))}) or "
                             f"materials, not {key!r}.")
        fixed_materials[label] = _number(value, f"the value fixed on {key}")
    for face, q in flux.items():
        if face not in face_names(ndim):
            raise ValueError(f"unknown face {face!r} for a flux; the faces of a {ndim}-D "
                             f"box are {', '.join(face_names(ndim))}.")
        _number(q, f"the flux on {face}")
    sources = _materials_table(source, names, "source") if source else {}
    if model == "fisher-kpp":
        if not rate > 0:
            raise ValueError(f"Fisher-KPP needs a positive proliferation rate, not {rate!r}.")
        if seed is None:
            raise ValueError("Fisher-KPP needs a seed ball: seed=((x, y[, z]), radius).")
        if fixed or flux or sources or decay:
            raise ValueError("fixed values, fluxes, sources and decay belong to the drug "
                             "model; Fisher-KPP starts from its seed.")
    elif rate:
        raise ValueError("rate is the Fisher-KPP proliferation rate; the drug model takes "
                         "decay.")
    elif not (fixed or flux or sources or seed is not None):
        raise ValueError("the drug model needs a source: fixed values, a flux, a volume "
                         "source or an initial seed ball.")
    centre = radius = None
    if seed is not None:
        try:
            centre_xyz, radius = seed
            centre_xyz = np.asarray(centre_xyz, dtype=float).reshape(-1)
            radius = float(radius)
        except (TypeError, ValueError):
            raise ValueError(f"seed must be ((x, y[, z]), radius), not {seed!r}.") from None
        if centre_xyz.size != ndim or not np.isfinite(centre_xyz).all() or not radius > 0:
            raise ValueError(f"seed must be a {ndim}-D centre and a positive radius, not "
                             f"{seed!r}.")
    # materials with D = 0 (and those not named) carry nothing: not meshed
    fisher = model == "fisher-kpp"
    widths = {m: float(np.sqrt(d / (rate if fisher else max(decay, 1e-300))))
              for m, d in table.items() if d > 0}
    if not fisher and decay == 0:
        widths = {m: np.inf for m in widths}
    sizes = bound_sizes(widths, front_cells)
    for m in fixed_materials:
        sizes.setdefault(m, np.inf)
    yield 0, saves, "meshing"
    if is_mesh:
        mesh = mesh_or_labels if not material_names else \
            mesh_or_labels.with_material_names(names)
        missing = sorted(set(np.unique(mesh.material).tolist()) - set(sizes))
        if missing:
            raise ValueError(f"materials {missing} of the mesh have no diffusivity; give "
                             "each a positive one, or mesh the labels without them "
                             "(materials of diffusivity 0 are left out of a label image's "
                             "mesh).")
        centre = None if seed is None else _seed_in_mesh(centre_xyz, mesh.world, ndim)
        reach = _reach(centre, radius, table, rate, duration, widths) if fisher else None
        ratio = size_ratio(mesh, sizes, reach)
        size = {"rounds": 0, "max_ratio": float(ratio.max(initial=0.0)),
                "met": bool(ratio.max(initial=0.0) <= 1 + 1e-9), "reason": "a mesh file"}
    else:
        lab = np.asarray(mesh_or_labels)
        present = set(np.unique(lab).tolist()) - set(int(e) for e in exclude)
        unused = [m for m in table if m not in present]
        if unused:
            raise ValueError(f"diffusivity names material {unused[0]}, which is not in the "
                             f"labels; the materials are {', '.join(map(str, sorted(present)))}.")
        left_out = tuple(sorted(set(int(e) for e in exclude) | (present - set(sizes))))
        if not present - set(left_out):
            raise ValueError("no material has a positive diffusivity; give one with D > 0.")
        spacing_arr = np.broadcast_to(np.asarray(1.0 if spacing is None else spacing,
                                                 dtype=float), (ndim,))
        centre = None if seed is None else centre_xyz[::-1].copy()
        reach = _reach(centre, radius, table, rate, duration, widths) if fisher else None
        mesh, size = front_mesh(lab, spacing=tuple(spacing_arr), exclude=left_out,
                                material_names=names, sizes=sizes, reach=reach)
    notes = []
    if not size["met"]:
        notes.append(f"elements the front reaches are up to {size['max_ratio']:.2g} times "
                     f"the size its width allows ({size['reason']}): the front speed may be "
                     + ("off; give the label image (it is refined) or a finer mesh."
                        if is_mesh else "off; ask fewer front cells or a shorter duration."
                        if front_cells > 1 else "off; ask a shorter duration or a smaller "
                        "image (the front is already meshed at its coarsest)."))
    t_mesh = time.perf_counter()
    result = yield from _run(mesh, table, fixed_faces, fixed_materials, flux, sources,
                             Reaction(model, rate, decay, kill), centre, radius, duration,
                             saves, error)
    result.seconds = {"mesh": t_mesh - t_start, "steps": time.perf_counter() - t_mesh}
    result.size = size
    result.warnings = notes + result.warnings
    for note in result.warnings:
        warnings.warn(note, UserWarning, stacklevel=3)
    return result


def _reach(centre, radius, table, rate, duration, widths) -> tuple[np.ndarray, float]:
    """The ball the Fisher-KPP front can reach by `duration` (with a margin of widths)."""
    speed = 2.0 * np.sqrt(max(table.values()) * rate)
    return centre, radius + speed * duration + REACH_MARGIN * max(widths.values(), default=0)


def _run(mesh, table, fixed_faces, fixed_materials, flux, sources, reaction, centre, radius,
         duration, saves, error):
    materials, cell_material = np.unique(mesh.material, return_inverse=True)
    d_fixed = max(table.values())
    d = np.array([table.get(int(m), d_fixed) or d_fixed for m in materials])
    tensors = d[:, None, None] * np.eye(mesh.ndim)
    stiffness = stiffness_matrix(fe_space(mesh, 1), tensors, cell_material).tocsr()
    volumes = signed_volumes(mesh.points, mesh.cells)
    n, corners = len(mesh.points), mesh.ndim + 1
    lumped = np.bincount(mesh.cells.ravel(), np.repeat(volumes / corners, corners),
                         minlength=n)
    off = stiffness - sparse.diags(stiffness.diagonal())
    positive = int(np.count_nonzero(off.data > 1e-12 * np.abs(stiffness.diagonal()).max()))
    notes = []
    if positive:
        notes.append(f"the stiffness has {positive} positive off-diagonal entries (obtuse "
                     "elements), so the bounds of c are kept by clipping, whose amount is "
                     "the balance's clipping term.")
    u = np.zeros(n)
    if centre is not None:
        inside = np.linalg.norm(mesh.points - centre, axis=1) <= radius
        if not inside.any():
            raise ValueError("the seed ball holds no vertex of the tissue; move it into a "
                             "material with a positive diffusivity or make it larger.")
        u[inside] = 1.0
    free = np.ones(n, dtype=bool)
    lo, hi = mesh.image_box()
    for face, value in fixed_faces.items():
        dofs = face_dofs(mesh.points.T, lo, hi, face)
        if dofs.size == 0:
            raise ValueError(f"no meshed material touches the {face} face, so a value fixed "
                             "there acts on nothing; fix another face.")
        free[dofs], u[dofs] = False, value
    for label, value in fixed_materials.items():
        dofs = np.unique(mesh.cells[mesh.material == label])
        if dofs.size == 0:
            raise ValueError(f"material {label} is not in the mesh, so a value fixed on it "
                             "acts on nothing.")
        free[dofs], u[dofs] = False, value
    load = _boundary_loads(mesh, flux)
    for label, s in sources.items():
        own = mesh.material == label
        load += np.bincount(mesh.cells[own].ravel(),
                            np.repeat(s * volumes[own] / corners, corners), minlength=n)
    fisher = reaction.model == "fisher-kpp"
    scale = 1.0 if fisher else max([abs(v) for v in (*fixed_faces.values(),
                                                     *fixed_materials.values())]
                                   + [1.0 if centre is not None else 0.0], default=0.0)
    if scale == 0:          # sources and fluxes only: their size over one decay time
        scale = float(np.sum(np.abs(load))) / max(float(lumped.sum()), 1e-300) * \
            min(duration, 1.0 / reaction.decay if reaction.decay > 0 else duration)
    scale = max(scale, 1e-300)
    stops = [duration * k / saves for k in range(1, saves + 1)]
    first = min(stops[0], 0.05 / max(reaction.rate, reaction.decay, 1e-300)) / 4
    times, values = [0.0], [u.copy()]
    amount = [float(lumped @ u)]
    balance = [dict.fromkeys(BALANCE_TERMS, 0.0)]
    record = None
    for record in imex_steps(lumped, stiffness, u, free, reaction, stops=stops, tol=error,
                             scale=scale, load=load, first_step=first,
                             upper=1.0 if fisher else None, ndim=mesh.ndim):
        if record.stop:
            times.append(record.time)
            values.append(record.values.copy())
            amount.append(float(lumped @ record.values))
            balance.append(record.balance)
        yield len(times) - 1, saves, f"t = {record.time:.4g} of {duration:g} " \
                                      f"({record.steps} steps)"
    return GrowthResult(np.array(times), np.stack(values), mesh, reaction.model,
                        {int(m): float(v) for m, v in zip(materials, d)},
                        None if centre is None else (centre, radius), np.array(amount),
                        {k: np.array([b[k] for b in balance]) for k in BALANCE_TERMS},
                        record.steps, record.rejected, warnings=notes)


def simulate_growth(mesh_or_labels, diffusivity: Mapping, *, duration: float,
                    model: str = "fisher-kpp", rate: float = 0.0, seed=None,
                    decay: float = 0.0, kill=(), fixed: Mapping | None = None,
                    flux: Mapping[str, float] | None = None, source: Mapping | None = None,
                    saves: int = 20, spacing=None, exclude=(),
                    material_names: Mapping[int, str] | None = None,
                    error: float = DEFAULT_GROWTH_ERROR,
                    front_cells: float = FRONT_CELLS) -> GrowthResult:
    """Tumour growth (Fisher-KPP) or drug delivery on the mesh of a label image.

    Parameters
    ----------
    mesh_or_labels : Mesh or (M, N[, P]) array_like of int
    diffusivity : mapping of int or str to float
        D per material, by label or name. Materials left out, or with D = 0, are not
        meshed (no flux into them: CSF, outside the brain); a mesh must have a positive
        D for every material.
    duration : float
        End time.
    model : {"fisher-kpp", "drug"}
    rate : float
        Fisher-KPP proliferation rate rho (per unit time).
    seed : ((x, y[, z]), radius), optional
        Ball where ``c = 1`` at t = 0, in the coordinates of the written files (x =
        column; physical units). Required for Fisher-KPP; an initial bolus for a drug.
    decay : float
        Drug uptake/decay rate lambda.
    kill : sequence of (start, end, rate)
        Kill rates ``-k c`` over time windows (chemotherapy cycles).
    fixed : mapping, optional
        Drug: fixed values on box faces (``"xmin"`` ... ``"zmax"``) or on materials.
    flux : mapping of str to float, optional
        Drug: inward flux density on box faces.
    source : mapping of int or str to float, optional
        Drug: volume source density per material.
    saves : int
        Saved times ``k * duration / saves``; the steps adapt within them.
    spacing, exclude, material_names
        As for :func:`simulate`.
    error : float
        Asked local error per step, a share of the field's scale (1 for Fisher-KPP, the
        largest fixed value for a drug).
    front_cells : float
        Elements per front width ``sqrt(D / rho)`` (drug: ``sqrt(D / lambda)``) in the
        part of the tissue the front can reach.

    Returns
    -------
    GrowthResult

    Examples
    --------
    A tumour filling a small square of one tissue: c stays within [0, 1] and grows.

    >>> labels = np.ones((8, 8), dtype=np.uint8)
    >>> r = simulate_growth(labels, {1: 0.5}, rate=1.0, seed=((4, 4), 1.5),
    ...                     duration=4.0, saves=2)
    >>> bool(r.values.min() >= 0 and r.values.max() <= 1), bool(r.amount[-1] > r.amount[0])
    (True, True)
    """
    gen = growth_steps(mesh_or_labels, diffusivity, duration=duration, model=model,
                       rate=rate, seed=seed, decay=decay, kill=kill, fixed=fixed, flux=flux,
                       source=source, saves=saves, spacing=spacing, exclude=exclude,
                       material_names=material_names, error=error, front_cells=front_cells)
    return run_steps(gen)
