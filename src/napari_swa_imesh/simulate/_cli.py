"""``swa-imesh simulate``: effective conductivity of a label image or a mesh file."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from .._cli_util import StepTimer, print_json
from ..io import IMAGE_SUFFIXES, image_suffix
from ._output import FIELD_SUFFIXES
from .reaction._cli import add_growth_arguments, run_growth

__all__ = ["add_commands"]


def add_commands(subparsers) -> None:
    """Register ``simulate`` on an argparse sub-parser group."""
    p = subparsers.add_parser(
        "simulate", help="effective conductivity of the image box (steady diffusion)",
        description="Steady diffusion / heat conduction on the IMESH mesh of a label image "
                    "(or on a mesh file with a material per element): for each axis, "
                    "potential 0 and 1 on the two faces normal to it, the other faces "
                    "insulated; k_eff = flux x length / area, checked against the Voigt "
                    "and Reuss bounds. Axes: x = column, y = row, z = plane.")
    p.add_argument("input", metavar="LABELS_OR_MESH",
                   help=f"label image ({', '.join(IMAGE_SUFFIXES)}) or mesh "
                        "(.vtu, .vtk, .msh, .xdmf, .inp, .node/.ele)")
    p.add_argument("--conductivity", "-k", nargs="+", action="extend", default=None,
                   metavar="MATERIAL=K",
                   help="conductivity per material, by label or name: 1=1 2=10 bone=0.1; "
                        "K1,K2[,K3] is a diagonal tensor in x, y(, z) order, d*d numbers "
                        "a full tensor row by row")
    p.add_argument("--spacing", type=float, nargs="+", default=None, metavar="S",
                   help="voxel size per axis in array order (labels only); default: from "
                        "the file, else 1")
    p.add_argument("--exclude", type=int, nargs="+", action="extend", default=[],
                   metavar="L", help="labels not to mesh (insulating voids; labels only)")
    p.add_argument("--material-names", nargs="+", action="extend", default=[],
                   metavar="ID=NAME", help="names for materials, usable in --conductivity")
    p.add_argument("--order", default="auto", metavar="auto|1|2",
                   help="element degree: 1 (linear), 2 (quadratic, more accurate per "
                        "unknown) or auto (default: for k_eff, P2 while its unknowns stay "
                        "within 3 million, else P1; P1 for boundary-value and transient runs)")
    p.add_argument("--adapt", default="auto", metavar="auto|0|1|2",
                   help="k_eff on labels: adaptive steps before the final solve (a P1 solve, "
                        "then the labels meshed again one level finer where the flux jumps "
                        "most); auto (default): one step with P2, or with --order 1 two steps "
                        "within 2.9x the vertices")
    p.add_argument("--refine", type=int, default=0, metavar="K",
                   help="labels only: elements at material interfaces are 2^-K voxels "
                        "(0..4, default 0), where the field is least smooth")
    p.add_argument("--max-aspect", type=float, default=None, metavar="A",
                   help="labels only: anisotropic voxels are cut into the fewest cells of "
                        "residual aspect <= A (default 1.25: radius-to-edge <= 1.3754, "
                        "dihedral angles >= 29.5 deg); larger, fewer elements and a looser "
                        "bound (swa-imesh bounds --spacing lists the choices)")
    p.add_argument("--protocol", choices=("mixed", "periodic"), default="mixed",
                   help="mixed (potential 0/1 on two faces, others insulated; default) or "
                        "periodic (unit mean gradient, periodic fluctuation: the full "
                        "tensor, printed and in --json as \"tensor\")")
    p.add_argument("--gap", type=float, default=2.0, metavar="PERCENT",
                   help="k_eff is printed as a certified interval (mixed protocol: the "
                        "conforming solution bounds it from above, an exactly divergence-"
                        "free flux from below); wider than this (default 2 %%) and with "
                        "--adapt auto, the labels are meshed again finer at the interfaces "
                        "until it closes or the refine levels or --memory run out, else a "
                        "warning gives the interval")
    p.add_argument("--no-interval", action="store_true",
                   help="skip the dual (lower-bound) solve: k_eff from above only")
    p.add_argument("--memory", default="4G", metavar="BYTES",
                   help="memory budget of a k_eff run (default 4G), checked from the mesh "
                        "before assembly with the estimate printed: the default order falls "
                        "back to P1 beyond it, an asked --order is refused")
    p.add_argument("--axes", nargs="+", choices=("x", "y", "z"), default=None,
                   help="axes to solve along (default: all)")
    p.add_argument("--tol", type=float, default=1e-10,
                   help="relative residual of the linear solve (default 1e-10)")
    b = p.add_argument_group(
        "boundary conditions", "with any of these, solve -div(k grad u) = f with conditions "
        "on the mesh's boundary facet groups (xmin..zmax, exterior_<A>) instead of k_eff; "
        "groups without one are insulated")
    b.add_argument("--dirichlet", nargs="+", action="extend", default=[],
                   metavar="GROUP=VALUE", help="fixed value on a group: xmin=1")
    b.add_argument("--neumann", nargs="+", action="extend", default=[],
                   metavar="GROUP=FLUX", help="inward flux density on a group (positive "
                                              "enters): xmax=0.5")
    b.add_argument("--robin", nargs="+", action="extend", default=[],
                   metavar="GROUP=H:UINF", help="exchange -k du/dn = H (u - UINF) on a "
                                                "group: zmax=10:20")
    b.add_argument("--source", nargs="+", action="extend", default=[],
                   metavar="MATERIAL=F", help="volume source density per material: 2=1.5")
    t = p.add_argument_group(
        "transient", "with --transient, solve c du/dt = div(k grad u) instead of k_eff, the "
        "mesh and time steps chosen for --error; faces not fixed are insulated")
    t.add_argument("--transient", type=float, default=None, metavar="DURATION",
                   help="end time of a transient run")
    t.add_argument("--steps", type=int, default=None,
                   help="saved times duration*k/steps (default 50); the time steps adapt "
                        "within them")
    t.add_argument("--error", default=None, metavar="E|fixed",
                   help="asked max error as a share of the largest jump of the fixed and "
                        "initial values (default 0.01): the mesh resolves the earliest saved "
                        "time's diffusion length and the steps adapt; the estimate is "
                        "printed, with a warning when it is exceeded. fixed: the mesh as "
                        "the labels give it and equal implicit Euler steps")
    t.add_argument("--fixed", nargs="+", action="extend", default=[], metavar="FACE=VALUE",
                   help="fixed values on box faces: xmin=1 (faces xmin..zmax)")
    t.add_argument("--initial", nargs="+", action="extend", default=[],
                   metavar="MATERIAL=VALUE",
                   help="initial value per material, by label or name (others 0)")
    t.add_argument("--capacity", nargs="+", action="extend", default=[],
                   metavar="MATERIAL=C",
                   help="capacity c per material, by label or name (others 1)")
    t.add_argument("--save-every", type=int, default=None, metavar="K",
                   help="write every K-th step (and the last)")
    p.add_argument("-o", "--output", default=None, metavar="FIELD",
                   help=f"write the mesh with potential and flux per axis "
                        f"({' or '.join(FIELD_SUFFIXES)}, for ParaView); with --transient "
                        "the time series (.xdmf with its .h5)")
    r = p.add_argument_group(
        "report", "the per-material signatures of the segmentation and k_eff in one table "
        "(k_eff runs only)")
    r.add_argument("--signatures", default=None, metavar="SIG.csv",
                   help="per-material signatures (swa-imesh segment --signatures), joined "
                        "by label (or name) to each material's volume fraction and "
                        "conductivity; printed, and \"materials\" in --json; their names "
                        "can be used in --conductivity")
    r.add_argument("--report", default=None, metavar="REPORT",
                   help="write the material table and k_eff (.csv, .json or .md)")
    from ._stochastic_args import add_stochastic_arguments

    add_stochastic_arguments(p)
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    add_growth_arguments(p)
    p.set_defaults(func=_run_simulate)


def _run_simulate(args: argparse.Namespace) -> int:
    from .._cli_util import parse_material_names
    from .._validation import normalize_spacing
    from ..io import read_image
    from ..mesh import image_placement, read_mesh
    from ._conductivity import parse_conductivity_args
    from ._output import check_field_path, check_series_path, write_field, write_series
    from ._report import (
        check_report_path,
        match_signatures,
        read_signatures,
        simulation_report,
        write_report,
    )
    from ._simulate import simulate
    from ._stochastic_args import stochastic_options

    if args.model != "conductivity":           # reaction-diffusion (issue 28)
        return run_growth(args)
    # the door: every argument and the output path before any work
    stochastic = stochastic_options(args)
    if stochastic is not None:
        return _run_stochastic(args, stochastic)
    conductivity = parse_conductivity_args(args.conductivity)
    names = parse_material_names(args.material_names)
    order = {"auto": "auto", "1": 1, "2": 2}.get(str(args.order))
    if order is None:
        raise ValueError(f"--order must be auto, 1 or 2, not {args.order}.")
    adapt = {"auto": "auto", "0": 0, "1": 1, "2": 2}.get(str(args.adapt))
    if adapt is None:
        raise ValueError(f"--adapt must be auto, 0, 1 or 2, not {args.adapt}.")
    from ._budget import parse_memory

    memory = parse_memory(args.memory)
    if not args.gap > 0:
        raise ValueError(f"--gap must be a positive percentage such as 2, not {args.gap:g}.")
    fixed_order = 1 if order == "auto" else order      # boundary-value and transient runs
    if not 0 < args.tol < 1:
        raise ValueError(f"--tol must lie between 0 and 1, not {args.tol:g}.")
    transient = _transient_options(args)
    boundary = _boundary_options(args)
    if boundary is not None and (transient is not None or args.axes
                                 or args.protocol != "mixed"):
        raise ValueError("--dirichlet/--neumann/--robin/--source solve one boundary-value "
                         "problem; they do not combine with --transient, --axes or "
                         "--protocol.")
    if (args.signatures or args.report) and (boundary is not None or transient is not None):
        raise ValueError("--signatures and --report join materials to k_eff; they do not "
                         "combine with --transient or boundary conditions.")
    signatures = None
    if args.signatures:
        signatures = read_signatures(args.signatures)
        # names from the signatures serve --conductivity too; --material-names must agree
        by_label, _ = match_signatures(signatures, names)
        names = {**{k: r["name"] for k, r in by_label.items() if r.get("name")}, **names}
    if args.report:
        check_report_path(args.report, force=args.force)
    if args.output and transient is None:
        check_field_path(args.output, force=args.force)
    elif args.output:
        check_series_path(args.output, force=args.force)
    is_image = image_suffix(args.input) in IMAGE_SUFFIXES
    if not is_image and (args.spacing or args.exclude or args.refine
                         or args.max_aspect is not None):
        raise ValueError("--spacing, --exclude, --refine and --max-aspect apply to a label "
                         "image; a mesh file already has its coordinates, materials and "
                         "elements.")
    if not is_image and adapt not in ("auto", 0):
        raise ValueError("--adapt meshes the labels again: it needs a label image, not a mesh "
                         "file (simulate the labels, or leave --adapt out).")
    from ..mesh import check_refine

    check_refine(args.refine)
    if args.max_aspect is not None:
        from ..mesh import check_max_aspect

        check_max_aspect(args.max_aspect, "--max-aspect")
    if transient is not None and args.protocol != "mixed":
        raise ValueError("--protocol is for the steady k_eff run, not --transient.")
    if transient is not None and args.refine:
        raise ValueError("--refine is for the steady k_eff run; for --transient, mesh with "
                         "swa-imesh mesh --refine K and simulate the mesh file.")
    if transient is not None and args.max_aspect is not None:
        raise ValueError("--max-aspect is for the steady k_eff run; for --transient, mesh "
                         "with swa-imesh mesh --max-aspect A and simulate the mesh file.")
    if args.spacing:
        normalize_spacing(args.spacing, len(args.spacing))

    timer = StepTimer()
    with timer("read"):
        if is_image:
            source, file_spacing = read_image(args.input)
            spacing = args.spacing or file_spacing
            # a NIfTI file's mesh is written in its world frame, as swa-imesh mesh does
            placement = None if args.spacing else image_placement(args.input, source.ndim)
            if placement is not None:
                spacing = placement[0]
        else:
            source, spacing, placement = read_mesh(args.input), None, None
            if not source.info.get("has_material", True):
                raise ValueError(f"{Path(args.input).name} has no material per element; "
                                 "simulate needs one (mesh the labels with swa-imesh mesh).")
            if signatures is not None:
                match_signatures(signatures, {**source.material_names, **names})
    if boundary is not None:
        from ._boundary import solve_boundary_value
        from ._simulate import prepare_mesh

        mesh = prepare_mesh(source, spacing=spacing if is_image else None,
                            exclude=tuple(args.exclude), material_names=names,
                            refine=args.refine, max_aspect=args.max_aspect)
        result = solve_boundary_value(mesh, conductivity, order=fixed_order, tol=args.tol,
                                      **boundary)
    elif transient is not None:
        from ._transient import simulate_transient

        result = simulate_transient(source, conductivity, spacing=spacing,
                                    order=fixed_order, tol=args.tol,
                                    exclude=tuple(args.exclude), material_names=names,
                                    **transient)
    else:
        with warnings.catch_warnings():   # said once, below, on stderr
            warnings.filterwarnings("ignore", message="the interval along")
            result = simulate(source, conductivity, spacing=spacing, order=order,
                              axes=args.axes, tol=args.tol, exclude=tuple(args.exclude),
                              material_names=names, refine=args.refine,
                              protocol=args.protocol, adapt=adapt if is_image else 0,
                              max_aspect=args.max_aspect, interval=not args.no_interval,
                              gap=args.gap / 100, memory=memory)
        if args.json:                     # the text output has them in its lines
            for note in result.warnings:
                print(f"warning: {note}", file=sys.stderr)
    if placement is not None and boundary is None:
        result.mesh.world = placement[1]
    table = None
    if signatures is not None or args.report:
        table = simulation_report(result, conductivity, signatures)
    written = []
    if args.output or args.report:
        with timer("write"):
            if args.output:
                write = write_series if transient is not None else write_field
                written = write(result, args.output, force=args.force)
            if args.report:
                written.append(write_report(table, args.report, force=args.force))
    seconds = {**timer.seconds, **result.seconds}
    if args.json:
        report = {"command": "simulate", "input": str(args.input), **result.summary(),
                  "output": [str(p) for p in written]}
        if table is not None:
            summary = table.summary()
            report.update(materials=summary["materials"], warnings=summary["warnings"])
        report["seconds"] = seconds
        print_json(report)
    else:
        print(result.describe())
        if table is not None:
            print(table.describe())
        if written:
            print(f"wrote {', '.join(map(str, written))}")
    return 0


def _transient_options(args) -> dict | None:
    """The keyword arguments of simulate_transient, or None for a steady run."""
    if args.transient is None:
        given = [flag for flag, value in (("--fixed", args.fixed), ("--initial", args.initial),
                                          ("--capacity", args.capacity),
                                          ("--steps", args.steps is not None),
                                          ("--error", args.error is not None),
                                          ("--save-every", args.save_every is not None))
                 if value]
        if given:
            raise ValueError(f"{given[0]} applies to a transient run; add --transient "
                             "DURATION.")
        return None
    if args.axes:
        raise ValueError("--axes chooses k_eff directions; a transient run takes --fixed "
                         "faces instead.")
    fixed = {}
    for item in args.fixed:
        face, sep, text = item.partition("=")
        try:
            fixed[face] = float(text) if sep else float("nan")
        except ValueError:
            fixed[face] = float("nan")
        if not sep or not np.isfinite(fixed[face]):
            raise ValueError(f"--fixed takes FACE=VALUE pairs such as xmin=1, not {item!r}.")
        if sum(other.partition("=")[0] == face for other in args.fixed) > 1:
            raise ValueError(f"--fixed gives face {face} twice; give each face one value.")
    for flag, value in (("--steps", args.steps), ("--save-every", args.save_every)):
        if value is not None and value < 1:
            raise ValueError(f"{flag} must be a positive whole number, not {value}.")
    from ._transient import DEFAULT_ERROR

    error = DEFAULT_ERROR if args.error is None else args.error
    if error != "fixed":
        try:
            error = float(error)
        except ValueError:
            raise ValueError(f"--error takes a share such as 0.01, or fixed, not "
                             f"{args.error!r}.") from None
    return {"duration": args.transient, "steps": 50 if args.steps is None else args.steps,
            "error": None if error == "fixed" else error,
            "fixed": fixed,
            "initial": _numbers(args.initial, "--initial", 0.0),
            "capacity": _numbers(args.capacity, "--capacity", 1.0),
            "save_every": 1 if args.save_every is None else args.save_every}


def _boundary_options(args) -> dict | None:
    """The keyword arguments of solve_boundary_value, or None for a k_eff run."""
    if not (args.dirichlet or args.neumann or args.robin or args.source):
        return None

    def pairs(items, flag, arity):
        out = {}
        for item in items:
            name, sep, text = item.partition("=")
            parts = text.split(":") if sep else []
            try:
                values = [float(v) for v in parts]
            except ValueError:
                values = []
            if not sep or not name or len(values) != arity or not np.isfinite(values).all():
                form = "GROUP=H:UINF such as zmax=10:20" if arity == 2 else \
                    "GROUP=VALUE such as xmin=1"
                raise ValueError(f"{flag} takes {form}, not {item!r}.")
            if name in out:
                raise ValueError(f"{flag} gives group {name} twice.")
            out[name] = values[0] if arity == 1 else tuple(values)
        return out

    return {"dirichlet": pairs(args.dirichlet, "--dirichlet", 1),
            "neumann": pairs(args.neumann, "--neumann", 1),
            "robin": pairs(args.robin, "--robin", 2),
            "source": _numbers(args.source, "--source", 0.0) or None}


def _numbers(items: list[str], flag: str, default: float) -> dict | float:
    if not items:
        return default
    out = {}
    for item in items:
        key, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = None
        if not sep or not key or value is None:
            raise ValueError(f"{flag} takes MATERIAL=VALUE pairs (a label or a material "
                             f"name), such as 2=1.5, not {item!r}.")
        if key in out:
            raise ValueError(f"{flag} gives material {key} twice.")
        out[key] = value
    return out


def _run_stochastic(args: argparse.Namespace, options: dict) -> int:
    """``simulate --stochastic``: k_eff of random fields from the signatures (issue 28)."""
    from .._cli_util import parse_material_names
    from ..io import read_image
    from ..mesh import check_refine, read_mesh
    from ._conductivity import parse_conductivity_args
    from ._stochastic import stochastic_k_eff
    from ._stochastic_result import write_stochastic

    names = parse_material_names(args.material_names)
    conductivity = parse_conductivity_args(args.conductivity) if args.conductivity else None
    is_image = image_suffix(args.input) in IMAGE_SUFFIXES
    if not is_image and (args.spacing or args.exclude or args.refine):
        raise ValueError("--spacing, --exclude and --refine apply to a label image; a mesh "
                         "file already has its coordinates, materials and elements.")
    check_refine(args.refine)
    timer = StepTimer()
    with timer("read"):
        if is_image:
            source, file_spacing = read_image(args.input)
            spacing = np.broadcast_to(np.asarray(args.spacing or file_spacing or 1.0,
                                                 dtype=np.float64), (source.ndim,))
        else:
            source, spacing = read_mesh(args.input), None
    # the tile side is in voxels for labels: the correlation length per axis in physical units
    correlation = options["tile_size"] * (spacing if spacing is not None else 1.0)
    result = stochastic_k_eff(
        source, options["signatures"], samples=options["samples"], correlation=correlation,
        property_map=options["property_map"], seed=options["seed"],
        conductivity=conductivity, spacing=spacing, exclude=tuple(args.exclude),
        material_names=names, refine=args.refine, order=options["order"], axes=args.axes,
        tol=args.tol, workers=options["workers"], scheduler=options["scheduler"],
        memory=options["memory"])
    written = []
    if options["table"] or options["histogram"]:
        with timer("write"):
            written = write_stochastic(result, table=options["table"],
                                       histogram=options["histogram"], force=args.force)
    if args.json:
        print_json({"command": "simulate", "input": str(args.input), "stochastic":
                    result.summary(), "output": [str(p) for p in written],
                    "seconds": {**timer.seconds, **result.seconds}})
    else:
        print(result.describe())
        if written:
            print(f"wrote {', '.join(map(str, written))}")
    return 0
