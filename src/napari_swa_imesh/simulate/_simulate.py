"""``simulate``: steady diffusion on the mesh, effective conductivity of the image box."""

from __future__ import annotations

import time
import warnings
from collections.abc import Generator, Mapping
from numbers import Real

import numpy as np

from .._steps import run_steps
from ..mesh import Mesh, mesh_labels
from ..mesh import refine_marked_tree as _refine_marked
from ._adapt import (
    AUTO,
    auto_settings,
    check_adapt,
    doerfler,
    flux_jump_indicator,
    refine_within,
    voxel_lattice_vertices,
)
from ._assembly import cell_fluxes, fe_space
from ._budget import (
    DEFAULT_MEMORY,
    check_memory,
    estimate_memory,
    fit_interval,
    format_bytes,
    unknowns,
)
from ._certify import (
    CERTIFY_UNKNOWNS,
    GAP_TARGET,
    check_gap,
    check_memory_budget,
    flux_scale,
    grades,
    keep_sharper,
    lower_bound,
    plan_refinement,
    relative_gaps,
    sharpen_interval,
)
from ._conductivity import axis_names, conductivity_tensors
from ._dual import facet_table
from ._fe import vertex_values
from ._hashin import HashinShtrikman, two_isotropic_phases
from ._periodic import PeriodicProblem
from ._periodic_dual import periodic_interval, periodic_upper
from ._pmultigrid import coarse_space, stiffness_operator
from ._protocols import BOUND_SLACK, check_within_bounds, mixed_boundary, voigt_reuss
from ._result import SimulationResult
from ._solve import DEFAULT_TOLERANCE, SolverInfo, element_parts

__all__ = ["SimulationResult", "simulate", "simulate_steps"]

ORDERS = (1, 2)
PROTOCOLS = ("mixed", "periodic")


def _check_axes(axes, ndim: int) -> tuple[str, ...]:
    names = axis_names(ndim)[::-1]                     # x, y(, z)
    if axes is None:
        return names
    if isinstance(axes, str):
        axes = tuple(axes) if set(axes) <= set("xyz") else (axes,)
    axes = tuple(axes)
    bad = [a for a in axes if a not in names]
    if bad or not axes or len(set(axes)) != len(axes):
        raise ValueError(f"axes must be distinct names among {', '.join(names)}, not "
                         f"{axes!r}.")
    return axes


def prepare_mesh(mesh_or_labels, *, spacing=None, exclude=(),
                 material_names: Mapping[int, str] | None = None, refine: int = 0,
                 periodic: bool = False, max_aspect: float | None = None) -> Mesh:
    """The mesh to simulate on: a given mesh (with extra names, not modified) or the
    IMESH mesh of a label image (refined at interfaces by `refine` levels, anisotropic
    voxels cut into cells of residual aspect at most `max_aspect`)."""
    if isinstance(mesh_or_labels, Mesh):
        if spacing is not None or tuple(exclude) or refine or max_aspect is not None:
            raise ValueError("spacing, exclude, max_aspect and refine apply to a label "
                             "image; a mesh already has them.")
        if not material_names:
            return mesh_or_labels
        names = {**mesh_or_labels.material_names, **dict(material_names)}
        return mesh_or_labels.with_material_names(names)
    return mesh_labels(mesh_or_labels, spacing=spacing, exclude=exclude,
                       material_names=dict(material_names or {}), refine=refine,
                       periodic=periodic, max_aspect=max_aspect)


def _check_box_faces(mesh: Mesh, names, lo: np.ndarray, hi: np.ndarray) -> None:
    """A mesh read from a file must have its box faces on axis planes for the protocol.

    A mesh placed in a rotated world frame (NIfTI) touches the planes of its bounding box
    at a few points only: the potential would be fixed on almost nothing and k_eff would
    be wrong. Refuse when a face to fix carries under 1 % of its area in facets.
    """
    from ..mesh import facet_groups

    groups = facet_groups(mesh)
    d = mesh.ndim
    extent = hi - lo
    for name in names:
        axis = d - 1 - "xyz".index(name)
        face_area = float(np.prod(np.delete(extent, axis)))
        for face in (f"{name}min", f"{name}max"):
            group = groups.get(face)
            area = 0.0 if group is None else float(_facet_measure(mesh.points[group.facets]).sum())
            if area < 0.01 * face_area:
                raise ValueError(
                    f"the mesh covers {100 * area / face_area:.2g} % of its {face} face: it "
                    "is not an axis-aligned box (a mesh in a rotated world frame, such as a "
                    "NIfTI mesh written without --index-space?), so the potential cannot be "
                    "fixed on that face. Simulate the label image, or a mesh written with "
                    "swa-imesh mesh --index-space.")


def _facet_measure(corners: np.ndarray) -> np.ndarray:
    """(F,) length (2-D) or area (3-D) of facets given by their (F, d, d) corners."""
    if corners.shape[1] == 2:
        return np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    return 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1)


def check_symmetric(tensor: np.ndarray) -> None:
    """A periodic tensor is symmetric; an asymmetric one means the solves stopped early."""
    solved = ~np.isnan(tensor).any(axis=0)
    block = tensor[np.ix_(solved, solved)]
    scale = float(np.abs(block).max(initial=0.0))
    if block.size and np.abs(block - block.T).max() > 1e-6 * scale:
        raise ValueError("the periodic tensor came out asymmetric beyond solver tolerance; "
                         "the solves did not converge far enough: lower --tol or the "
                         "conductivity contrast.")


def check_tolerance(tol) -> None:
    if isinstance(tol, bool) or not isinstance(tol, Real) or not 0 < tol < 1:
        raise ValueError(f"tol must be a relative residual between 0 and 1, not {tol!r}.")


def simulate_steps(mesh_or_labels, conductivity: Mapping, *, spacing=None,
                   order: int | str = AUTO, axes=None, tol: float = DEFAULT_TOLERANCE,
                   exclude=(), material_names: Mapping[int, str] | None = None,
                   refine: int = 0, protocol: str = "mixed", adapt: int | str = AUTO,
                   labels=None, max_aspect: float | None = None,
                   interval: bool = True, gap: float = GAP_TARGET,
                   memory: float = DEFAULT_MEMORY
                   ) -> Generator[tuple[int, int, str], None, SimulationResult]:
    """Run :func:`simulate` step by step, for a progress bar.

    Parameters
    ----------
    mesh_or_labels, conductivity, spacing, order, axes, tol, exclude, material_names, refine,
    protocol, adapt, labels, max_aspect, interval, gap, memory
        As for :func:`simulate`.

    Yields
    ------
    (done, total, message) : (int, int, str)
        Progress: assembly, then one solve per axis.

    Returns
    -------
    SimulationResult
        As the generator's return value (``StopIteration.value``).
    """
    if order != AUTO and (isinstance(order, bool) or order not in ORDERS):
        raise ValueError(f"order must be 1 or 2 (P1 or P2 elements) or 'auto', not {order!r}.")
    adapt = check_adapt(adapt)
    may_refine = adapt == AUTO          # an asked mesh (adapt given) is kept as asked
    check_tolerance(tol)
    gap_target = check_gap(gap)
    check_memory_budget(memory)
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, not {protocol!r}.")
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    mesh = prepare_mesh(mesh_or_labels, spacing=spacing, exclude=exclude,
                        material_names=material_names, refine=refine,
                        periodic=protocol == "periodic", max_aspect=max_aspect)
    names = _check_axes(axes, mesh.ndim)
    materials, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = conductivity_tensors(conductivity, materials, mesh.ndim, mesh.material_names)
    source = labels if isinstance(mesh_or_labels, Mesh) else mesh_or_labels
    # the P1 default's budget counts from the labels on voxel cells, not from a mesh the
    # spacing's subdivision made finer (only computed where it decides something)
    reference = (voxel_lattice_vertices(source, mesh)
                 if order == 1 and adapt == AUTO and source is not None
                 and mesh.recipe is not None and mesh.recipe.remeshable else None)
    chosen = order
    order, adapt, growth, choice = auto_settings(mesh, order, adapt, source is not None,
                                                 reference)
    pbc, interval_wanted = protocol == "periodic", bool(interval) and protocol == "mixed"
    periodic_wanted = bool(interval) and protocol == "periodic" and mesh.ndim == 2
    if chosen == AUTO and order == 2 and check_memory(mesh, 2, interval_wanted, memory,
                                                      asked=False, periodic=pbc):
        order, adapt, growth, choice = auto_settings(mesh, 1, 0, source is not None)
        choice = (f"P1 (P2 would need about "
                  f"{format_bytes(estimate_memory(mesh, 2, interval_wanted, pbc))}, above the "
                  f"memory budget of {format_bytes(memory)})")
    interval_wanted, skipped = fit_interval(mesh, order, interval_wanted, memory)
    check_memory(mesh, order, interval_wanted, memory, asked=True, periodic=pbc)  # before any solve
    start = len(mesh.points)
    seconds["mesh"] = time.perf_counter() - t0
    total = 2 + len(names) + adapt
    tree = None                # the tree of the last adapted mesh, for the next step
    for step in range(adapt):
        yield 1 + step, total, (f"adaptive step {step + 1}: P1 on {mesh.n_cells} elements, "
                                "refining where the flux jumps most")
        t0 = time.perf_counter()
        first = simulate(mesh, conductivity, order=1, adapt=0, axes=names, tol=tol,
                         protocol=protocol, interval=False)
        # mark whole leaves (the unit the mesher splits) by their summed indicator
        leaf = np.asarray(mesh.cell_data["leaf"])
        indicator = np.bincount(leaf, flux_jump_indicator(mesh, [first.flux[a] for a in names]))
        del first          # its fields would stay alive through the next mesh and solve
        if growth is None:
            mesh, tree = _refine_marked(source, mesh, doerfler(indicator)[leaf], tree)
        else:              # P1's default: each step its share of the vertex budget
            target = start * growth ** ((step + 1) / adapt)
            mesh, tree = refine_within(source, mesh, indicator, target, tree)
        materials, cell_material = np.unique(mesh.material, return_inverse=True)
        seconds[f"adapt {step + 1}"] = time.perf_counter() - t0
    k_eff, bounds, potential, flux, solver = {}, {}, {}, {}, {}
    upper: dict[str, float] = {}
    interval: dict[str, tuple[float, float]] = {}
    dual_info: dict[str, SolverInfo] = {}
    certify = 0
    growth_seen, graded = 1.0, False
    done = 1 + adapt
    interval_wanted, skipped = fit_interval(mesh, order, interval_wanted, memory, skipped)
    check_memory(mesh, order, interval_wanted, memory, asked=True, periodic=pbc)
    notes: list[str] = [skipped] if skipped else []
    while True:
        yield done, total, f"assembling P{order} on {mesh.n_cells} elements"
        t0 = time.perf_counter()
        space = fe_space(mesh, order)
        volumes = np.empty(mesh.n_cells)
        matrix = stiffness_operator(space, tensors, cell_material, volumes, periodic=pbc)
        doflocs = space.doflocs
        coarse = coarse_space(matrix, space)
        seconds["assemble"] = seconds.get("assemble", 0.0) + time.perf_counter() - t0
        lo, hi = mesh.image_box()
        per_material = np.bincount(cell_material, weights=volumes, minlength=materials.size)
        fractions = per_material / float(np.prod(hi - lo))
        if not mesh.records_box:
            _check_box_faces(mesh, names, lo, hi)
        if not mesh.records_box and fractions.sum() < 1 - 1e-9:
            warnings.warn("the mesh has voids and does not record the image box, so the box "
                          "is the extent of its points; if an excluded material covered a "
                          "whole face of the image, k_eff refers to a smaller box: simulate "
                          "the label image instead.", stacklevel=2)
        image_axes = {n: i for i, n in enumerate(axis_names(mesh.ndim))}
        parts = element_parts(mesh.cells, len(mesh.points), space.edges)
        last: dict = {}           # the energy's pass over the elements also gives the flux

        def energy(u: np.ndarray, space=space, cell_material=cell_material,
                   last=last) -> float:
            last["u"], (last["flux"], total) = u, cell_fluxes(space, u, tensors, cell_material)
            return total

        seconds.setdefault("solve", 0.0)
        periodic = tensor = None
        if protocol == "periodic":
            t0 = time.perf_counter()
            periodic = PeriodicProblem(matrix, doflocs, lo, hi, tol=tol,
                                       cell_vertices=space.element_dofs[:, :mesh.ndim + 1].T)
            tensor = np.full((mesh.ndim, mesh.ndim), np.nan)
            seconds["solve"] += time.perf_counter() - t0
        dual_space = facets = None
        gap_indicator = np.zeros(mesh.n_cells) if interval_wanted else None
        sharp = not grades(mesh, mesh_or_labels, may_refine)   # the curl on the last mesh
        for step, name in enumerate(names, start=done + 1):
            yield step, total, f"solving along {name} ({matrix.shape[0]} unknowns)"
            t0 = time.perf_counter()
            axis = image_axes[name]
            if periodic is None:
                result = mixed_boundary(matrix, doflocs, name, lo, hi, energy, tol=tol,
                                        parts=parts, cell_dofs=space.element_dofs,
                                        cell_material=mesh.material, coarse=coarse)
                value, values, info = result.k_eff, result.values, result.info
            else:
                tensor[:, axis], values, info = periodic.solve(axis)
                value = float(tensor[axis, axis])
                if periodic_wanted:
                    upper[name] = periodic_upper(matrix, values, float(np.prod(hi - lo)))
            voigt, reuss = voigt_reuss(tensors, fractions, axis)
            check_within_bounds(value, voigt, reuss, name)
            k_eff[name] = value
            bounds[name] = (reuss, voigt)
            solver[name] = info
            potential[name] = vertex_values(values, len(mesh.points))
            cells_flux = last["flux"] if last.get("u") is values else cell_fluxes(
                space, values, tensors, cell_material)[0]                   # (M, d) axis order
            flux[name] = np.ascontiguousarray(cells_flux[:, ::-1])
            last.clear()
            del cells_flux
            seconds["solve"] += time.perf_counter() - t0
            if interval_wanted:
                t0 = time.perf_counter()
                dual_space = fe_space(mesh, 1) if dual_space is None else dual_space
                facets = facet_table(mesh.cells) if facets is None else facets
                dual = lower_bound(mesh, space, dual_space, tensors, cell_material, axis,
                                   lo, hi, tol=tol, facets=facets, memory=memory,
                                   upper=value, gap=gap_target,
                                   sharpen=sharp)
                kept = keep_sharper(dual.k_lower, interval.get(name))
                if kept > value * (1 + BOUND_SLACK):
                    raise ValueError(f"along {name} the dual bound {kept:.9g} lies "
                                     f"above the primal {value:.9g}: one of the solves is "
                                     "wrong; please report this with the input.")
                interval[name] = (min(kept, value), value)
                dual_info[name] = dual.info
                # the gap per element, relative to this axis' flux: axes weigh the same
                gap_indicator += dual.hypercircle(space, values, tensors, cell_material
                                                  ) / (value * flux_scale(lo, hi, axis))
                del dual
                seconds["dual"] = seconds.get("dual", 0.0) + time.perf_counter() - t0
        done += 1 + len(names)
        wide = {a: g for a, g in relative_gaps(interval).items() if g > gap_target}
        if not wide:
            break
        plan = plan_refinement(mesh, mesh_or_labels, refine + certify + 1, gap_indicator,
                               order=order, may_refine=may_refine, growth_seen=growth_seen,
                               memory=memory, interval=interval_wanted, graded=graded)
        why = plan.why
        if why is None:
            yield done, total + 2 + len(names), (
                f"interval wider than {100 * gap_target:g} %: {plan.message}")
            t0 = time.perf_counter()
            if plan.target is None:
                finer, tree = prepare_mesh(source, spacing=spacing, exclude=exclude,
                                           material_names=material_names, refine=plan.level,
                                           max_aspect=max_aspect), None
            else:                # graded by the gap, from the tree of the last step
                finer, tree = refine_within(source, mesh, plan.leaf_gap, plan.target, tree)
            graded = plan.target is not None
            seconds[f"certify {certify + 1}"] = time.perf_counter() - t0
            cap = CERTIFY_UNKNOWNS[mesh.ndim]
            why = check_memory(finer, order, interval_wanted, memory, asked=False)
            if why is None and unknowns(finer, order) > cap:
                why = (f"the next refinement would take about {unknowns(finer, order):,} "
                       f"unknowns, above the {cap:,} the interval's refinement may take "
                       "(pass --refine to go further)")
            if why is None:
                del matrix, space, coarse, parts, periodic, dual_space, facets
                if certify and plan.target is None:   # from one interface level to the
                    growth_seen = finer.n_cells / mesh.n_cells   # next (not adapt's mesh)
                mesh = finer
                materials, cell_material = np.unique(mesh.material, return_inverse=True)
                certify += 1
                total += 2 + len(names)
                continue
        if not sharp:       # not graded after all: the curl skipped for the next mesh
            t0 = time.perf_counter()
            wide = sharpen_interval(interval, dual_info, wide, mesh, space, dual_space,
                                    tensors, cell_material, image_axes, lo, hi, tol=tol,
                                    facets=facets, memory=memory, gap=gap_target)
            seconds["dual"] += time.perf_counter() - t0
            if not wide:
                break
        widest = max(wide, key=wide.get)
        lo_k, hi_k = interval[widest]
        notes.append(f"the interval along {widest} is {lo_k:.6g} .. {hi_k:.6g} (gap "
                     f"{100 * wide[widest]:.3g} %), wider than the target "
                     f"{100 * gap_target:g} %, and {why}: k_eff is certain only to within "
                     "that interval.")
        break
    seconds["setup"] = sum(info.setup for info in solver.values())
    if periodic_wanted:         # 2-D periodic: bounds of the tensor (:mod:`._periodic_dual`)
        t0 = time.perf_counter()
        interval, dual_info, note = periodic_interval(space, tensors, cell_material, lo, hi,
                                                      upper, image_axes, tol, gap_target)
        notes += note
        seconds["dual"] = time.perf_counter() - t0
    if tensor is not None:
        check_symmetric(tensor)
    hashin = None
    phases = two_isotropic_phases(tensors, fractions)
    if phases is not None:
        full = tensor is not None and not np.isnan(tensor).any()
        hashin = HashinShtrikman.of(*phases, mesh.ndim, tensor if full else None)
    for note in notes:
        warnings.warn(note, stacklevel=2)
    if certify:
        choice += f", {certify} step{'s' * (certify > 1)} refined for the interval"
    yield total, total, "done"
    return SimulationResult(
        k_eff=k_eff, bounds=bounds, potential=potential, flux=flux, solver=solver,
        volume_fractions={int(m): float(f) for m, f in zip(materials, fractions)},
        mesh=mesh, order=order, dofs=int(matrix.shape[0]), seconds=seconds,
        protocol=protocol, tensor=None if tensor is None else tensor[::-1, ::-1].copy(),
        hashin_shtrikman=hashin, adapt=adapt, choice=choice, interval=interval,
        gap_target=gap_target, certify=certify, dual_solver=dual_info, warnings=notes,
        memory_estimate=estimate_memory(mesh, order, interval_wanted, pbc), memory=float(memory))


def simulate(mesh_or_labels, conductivity: Mapping, *, spacing=None,
             order: int | str = AUTO, axes=None, tol: float = DEFAULT_TOLERANCE, exclude=(),
             material_names: Mapping[int, str] | None = None,
             refine: int = 0, protocol: str = "mixed", adapt: int | str = AUTO,
             labels=None, max_aspect: float | None = None, interval: bool = True,
             gap: float = GAP_TARGET, memory: float = DEFAULT_MEMORY) -> SimulationResult:
    """Steady diffusion on an IMESH mesh: effective conductivity of the image box.

    For each axis asked, the mixed-boundary protocol: potential 0 and 1 on the two faces
    normal to the axis, every other boundary insulated; ``k_eff = flux * length / area``.

    Parameters
    ----------
    mesh_or_labels : Mesh or (M, N[, P]) array_like of int
        A mesh from :func:`~napari_swa_imesh.mesh.mesh_labels`, or a label image to mesh
        first (with `spacing` and `exclude`).
    conductivity : mapping of int or str to float, (d,) or (d, d) array_like
        Per material, by label or name: a positive number, the diagonal in x, y(, z)
        order, or a symmetric positive definite tensor in the x, y(, z) frame. Every
        meshed material needs one; excluded materials conduct nothing.
    spacing : float or sequence of float, optional
        Voxel size per axis (labels only).
    order : {"auto", 1, 2}
        Lagrange element degree. P2 is the more accurate per unknown on these meshes;
        ``"auto"`` (the default) takes P2 while its unknowns stay within
        :data:`~._adapt.P2_BUDGET`, else P1 (``result.choice`` says which and why).
    axes : sequence of {"x", "y", "z"}, optional
        Axes to solve along (x = column, y = row, z = plane); default all.
    tol : float
        Relative residual of the conjugate-gradient solve (AMG-preconditioned).
    exclude : iterable of int
        Materials not to mesh (labels only); they act as insulating voids.
    material_names : mapping of int to str, optional
        Names for materials, usable as keys of `conductivity`.
    refine : int
        Labels only: mesh with elements of ``2**-refine`` voxels at material interfaces
        (``mesh_labels(refine=...)``), where the field is least smooth.
    protocol : {"mixed", "periodic"}
        ``"mixed"``: the protocol above, k_eff per axis. ``"periodic"``: a unit mean
        gradient along each axis with a periodic fluctuation (opposite faces matched;
        labels are meshed with ``periodic=True``, a mesh must have matching faces); gives
        the full tensor (``result.tensor``) and k_eff as its diagonal. For an image that
        is not periodic the two bracket the answer less tightly than either alone.
    adapt : {"auto", 0, 1, 2}
        Adaptive steps before the final solve: a P1 solve, its flux-jump indicator, and
        the labels meshed again one level finer where it is largest (:mod:`._adapt`).
        ``"auto"``: one step with P2 when the labels are at hand and the budget allows;
        with ``order=1``, two steps that together reach at most 2.9 times the vertices of
        the labels meshed on voxel cells (the leaves of largest indicator split first;
        :func:`._adapt.refine_within`); a lattice subdivided for the spacing counts
        toward that budget.
    labels : (M, N[, P]) array_like of int, optional
        With a mesh: the label image it was made from, so that it can be adapted.
    max_aspect : float, optional
        Labels only: largest residual aspect of the lattice cells anisotropic voxels are
        cut into (``mesh_labels(max_aspect=...)``; default 1.25).
    interval : bool
        Mixed protocol: also bound k_eff from below (:mod:`._dual`), so that
        ``result.interval[axis] = (lower, upper)`` contains the exact k_eff of the meshed
        geometry. The upper bound is k_eff itself (the conforming solution's energy with
        the potential exactly 0/1 on the two faces, the rest insulated); the lower is the
        complementary energy of a divergence-free flux with no normal component on the
        insulated boundary (sides and excluded materials). Both hold for these boundary
        conditions only; the periodic protocol has no interval.
    gap : float
        Target ``(upper - lower) / lower`` (default 2 %): wider, and with `adapt` left
        to ``"auto"``, the labels are meshed again with interface elements one level
        finer (``refine + 1``, ...), while refine levels, `memory` and
        :data:`CERTIFY_UNKNOWNS` allow; still wider
        at the end, a warning gives the interval (also in ``result.warnings``).
    memory : float
        Budget in bytes (default 4 GiB), checked from the mesh before assembly
        (:mod:`._budget`): the default order falls back to P1 beyond it, an asked order
        is refused with a ValueError, a refinement for the interval is not made.

    Returns
    -------
    SimulationResult

    Examples
    --------
    Two layers in series along x, conductivities 1 and 3: the harmonic mean.

    >>> import numpy as np
    >>> labels = np.ones((4, 8), dtype=np.uint8); labels[:, 4:] = 2
    >>> r = simulate(labels, {1: 1.0, 2: 3.0}, axes="x")
    >>> round(r.k_eff["x"], 9)
    1.5
    """
    steps = simulate_steps(mesh_or_labels, conductivity, spacing=spacing, order=order,
                           axes=axes, tol=tol, exclude=exclude, material_names=material_names,
                           refine=refine, protocol=protocol, adapt=adapt, labels=labels,
                           max_aspect=max_aspect, interval=interval, gap=gap, memory=memory)
    return run_steps(steps)
