"""``swa-imesh simulate --model fisher-kpp|drug``: reaction-diffusion from the command line.

The options join ``simulate``'s own: ``--steps`` (saved times), ``--error``, ``--fixed``
(faces or materials), ``--neumann`` (face fluxes) and ``--source`` (per material) mean
for the drug what they mean for the other runs; the rest are this group's.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_growth_arguments", "run_growth"]

#: ``--model`` choices; ``conductivity`` is the steady (or ``--transient``) run.
MODELS = ("conductivity", "fisher-kpp", "drug")


def add_growth_arguments(p: argparse.ArgumentParser) -> None:
    """Add the reaction-diffusion options to the ``simulate`` parser.

    Parameters
    ----------
    p : argparse.ArgumentParser
    """
    p.add_argument("--model", choices=MODELS, default="conductivity",
                   help="conductivity (k_eff, or --transient diffusion; default), "
                        "fisher-kpp (tumour growth dc/dt = div(D grad c) + rho c (1 - c)) "
                        "or drug (dc/dt = div(D grad c) - lambda c + sources)")
    g = p.add_argument_group(
        "reaction-diffusion", "with --model fisher-kpp or drug: materials without a "
        "diffusivity (or D = 0: CSF, outside) are not meshed and take no flux; -o writes "
        "the series (.xdmf + .h5), the table <stem>.csv (volume above --threshold and "
        "front distance per material, the balance) and the plot <stem>.png")
    g.add_argument("-D", "--diffusivity", nargs="+", action="extend", default=[],
                   metavar="MATERIAL=D", help="diffusivity per material: 2=0.1 3=0.02")
    g.add_argument("--duration", type=float, default=None, metavar="T", help="end time")
    g.add_argument("--rate", type=float, default=None, metavar="RHO",
                   help="fisher-kpp: proliferation rate")
    g.add_argument("--seed", default=None, metavar="X,Y[,Z]:R",
                   help="ball where c = 1 at t = 0 (the written files' coordinates: world "
                        "x, y(, z) for a NIfTI file, unless --spacing is given); "
                        "required for fisher-kpp, an initial bolus for drug")
    g.add_argument("--kill", nargs="+", action="extend", default=[],
                   metavar="START:END:RATE", help="kill rate over a time window "
                                                  "(chemotherapy cycles): 10:12:0.5")
    g.add_argument("--decay", type=float, default=None, metavar="LAMBDA",
                   help="drug: uptake/decay rate")
    g.add_argument("--threshold", type=float, default=0.5, metavar="C",
                   help="c above which an element counts as tumour (default 0.5)")
    g.add_argument("--front-cells", type=float, default=None, metavar="N",
                   help="elements per front width sqrt(D/rho) (drug: sqrt(D/lambda)) where "
                        "the front can reach (default 4)")


def _pairs(items, flag: str, form: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items:
        key, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not sep or not key or not np.isfinite(value):
            raise ValueError(f"{flag} takes {form}, not {item!r}.")
        if key in out:
            raise ValueError(f"{flag} gives {key} twice; give each one value.")
        out[key] = value
    return out


def _seed(text: str) -> tuple[tuple[float, ...], float]:
    centre, sep, radius = text.partition(":")
    try:
        xyz = tuple(float(v) for v in centre.split(","))
        r = float(radius)
    except ValueError:
        xyz, r = (), float("nan")
    if not sep or len(xyz) not in (2, 3) or not np.isfinite([*xyz, r]).all() or r <= 0:
        raise ValueError(f"--seed takes X,Y[,Z]:R with a positive radius, such as "
                         f"12,20,8:3, not {text!r}.")
    return xyz, r


def _seed_from_world(seed, world: np.ndarray) -> tuple[tuple[float, ...], float]:
    """The seed ball given in world x, y(, z) as the library takes it for a label image
    (x, y(, z) = the array's axes reversed); the radius is kept, since the linear part of
    ``world`` is a rotation (or a reflection) unless the affine shears."""
    centre, radius = seed
    d = len(world) - 1
    if len(centre) != d:
        return seed                   # the library says what is wrong
    index = np.linalg.solve(world[:d, :d], np.asarray(centre, dtype=float) - world[:d, d])
    return tuple(float(v) for v in index[::-1]), radius


def _kill(items) -> list[tuple[float, float, float]]:
    out = []
    for item in items:
        try:
            a, b, r = (float(v) for v in item.split(":"))
        except ValueError:
            raise ValueError(f"--kill takes START:END:RATE, such as 10:12:0.5, not "
                             f"{item!r}.") from None
        if not (0 <= a < b and r >= 0):
            raise ValueError(f"--kill needs 0 <= START < END and RATE >= 0, not {item!r}.")
        out.append((a, b, r))
    return out


def _options(args) -> dict:
    """The keyword arguments of simulate_growth, checked at the door."""
    model = args.model
    foreign = [flag for flag, given in (
        ("--conductivity", args.conductivity), ("--transient", args.transient is not None),
        ("--stochastic", getattr(args, "stochastic", None) is not None),
        ("--dirichlet", args.dirichlet), ("--robin", args.robin), ("--axes", args.axes),
        ("--initial", args.initial), ("--capacity", args.capacity),
        ("--signatures", args.signatures), ("--report", args.report),
        ("--refine", args.refine), ("--max-aspect", args.max_aspect is not None),
        ("--protocol", args.protocol != "mixed"), ("--save-every", args.save_every))
        if given]
    if foreign:
        raise ValueError(f"{foreign[0]} is for the conductivity model; --model {model} "
                         "takes -D, --duration and its own options (see --help).")
    if not args.diffusivity:
        raise ValueError(f"--model {model} needs -D MATERIAL=D for the materials that "
                         "carry it, such as -D 2=0.1 3=0.02.")
    if args.duration is None or not args.duration > 0:
        raise ValueError(f"--model {model} needs a positive --duration T.")
    fisher = model == "fisher-kpp"
    if fisher and (args.fixed or args.neumann or args.source or args.decay is not None):
        raise ValueError("--fixed, --neumann, --source and --decay belong to --model drug; "
                         "fisher-kpp starts from --seed.")
    if not fisher and args.rate is not None:
        raise ValueError("--rate is fisher-kpp's proliferation rate; --model drug takes "
                         "--decay.")
    if fisher and (args.rate is None or not args.rate > 0):
        raise ValueError("--model fisher-kpp needs a positive --rate RHO.")
    if fisher and args.seed is None:
        raise ValueError("--model fisher-kpp needs --seed X,Y[,Z]:R, the ball where the "
                         "tumour starts.")
    if not 0 < args.threshold < 1:
        raise ValueError(f"--threshold must lie between 0 and 1, not {args.threshold:g}.")
    if args.steps is not None and args.steps < 1:
        raise ValueError(f"--steps must be a positive whole number, not {args.steps}.")
    out: dict[str, Any] = {"model": model, "duration": args.duration,
           "diffusivity": _pairs(args.diffusivity, "-D", "MATERIAL=D pairs such as 2=0.1"),
           "saves": 20 if args.steps is None else args.steps,
           "kill": _kill(args.kill)}
    if any(v < 0 for v in out["diffusivity"].values()):
        raise ValueError("-D takes diffusivities >= 0 (0: not meshed, no flux).")
    if args.error is not None:
        try:
            out["error"] = float(args.error)
        except ValueError:
            raise ValueError(f"--error takes a share such as 1e-3, not {args.error!r}.") \
                from None
        if not 0 < out["error"] < 1:
            raise ValueError(f"--error must lie between 0 and 1, not {args.error}.")
    if args.front_cells is not None:
        if not args.front_cells >= 1:
            raise ValueError(f"--front-cells must be at least 1, not {args.front_cells:g}.")
        out["front_cells"] = args.front_cells
    if args.seed is not None:
        out["seed"] = _seed(args.seed)
    if fisher:
        out["rate"] = args.rate
    else:
        out["decay"] = 0.0 if args.decay is None else args.decay
        if out["decay"] < 0:
            raise ValueError(f"--decay must not be negative, not {args.decay:g}.")
        out["fixed"] = _pairs(args.fixed, "--fixed", "FACE=VALUE or MATERIAL=VALUE")
        out["flux"] = _pairs(args.neumann, "--neumann", "FACE=FLUX such as xmin=0.5")
        out["source"] = _pairs(args.source, "--source", "MATERIAL=F such as 2=1.5") or None
        if not (out["fixed"] or out["flux"] or out["source"] or args.seed):
            raise ValueError("--model drug needs a source: --fixed, --neumann, --source or "
                             "--seed.")
    return out


def run_growth(args: argparse.Namespace) -> int:
    """Run ``simulate --model fisher-kpp|drug`` (after the door's checks).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``simulate`` arguments.

    Returns
    -------
    int
        The exit status (0).
    """
    from ..._cli_util import StepTimer, parse_material_names, print_json
    from ..._validation import normalize_spacing
    from ...io import IMAGE_SUFFIXES, image_suffix, read_image
    from ...mesh import image_placement, read_mesh
    from .._growth import simulate_growth
    from .._growth_output import growth_outputs, growth_table, write_growth

    options = _options(args)
    names = parse_material_names(args.material_names)
    if args.output:
        growth_outputs(args.output, force=args.force)
    is_image = image_suffix(args.input) in IMAGE_SUFFIXES
    if not is_image and (args.spacing or args.exclude):
        raise ValueError("--spacing and --exclude apply to a label image; a mesh file "
                         "already has its coordinates and materials.")
    if args.spacing:
        normalize_spacing(args.spacing, len(args.spacing))
    timer = StepTimer()
    source: Any
    with timer("read"):
        if is_image:
            source, file_spacing = read_image(args.input)
            extra: dict[str, Any] = {"spacing": args.spacing or file_spacing,
                                     "exclude": tuple(args.exclude)}
            # a NIfTI file's mesh is written in its world frame, as swa-imesh mesh does
            placement = None if args.spacing else image_placement(args.input, source.ndim)
            if placement is not None:
                extra["spacing"] = placement[0]
                if options.get("seed") is not None:
                    options["seed"] = _seed_from_world(options["seed"], placement[1])
        else:
            source, extra, placement = read_mesh(args.input), {}, None
            if not source.info.get("has_material", True):
                raise ValueError(f"{Path(args.input).name} has no material per element; "
                                 "simulate needs one (mesh the labels with swa-imesh mesh).")
    result = simulate_growth(source, material_names=names, **extra, **options)
    if placement is not None:
        result.mesh.world = placement[1]
    written = []
    if args.output:
        with timer("write"):
            written = write_growth(result, args.output, threshold=args.threshold,
                                   force=args.force)
    table = growth_table(result, threshold=args.threshold)
    if args.json:                   # its warnings were shown on stderr as they came
        report = {"command": "simulate", "input": str(args.input), **result.summary(),
                  "volume": table["volume"].tolist(),
                  "output": [str(p) for p in written],
                  "seconds": {**timer.seconds, **result.seconds}}
        print_json(report)
    else:
        print(result.describe())
        print(f"volume with c > {args.threshold:g}: {table['volume'][0]:.6g} at t = 0, "
              f"{table['volume'][-1]:.6g} at t = {table['time'][-1]:g}")
        if written:
            print(f"wrote {', '.join(map(str, written))}")
    return 0
