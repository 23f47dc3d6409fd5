"""The ``simulate --stochastic`` options: their argument group and their check at the door.

Kept apart from ``_cli.py`` (which only registers the group and hands a stochastic run
to its runner) so the command's module stays small; nothing here prints or exits.
"""

from __future__ import annotations

import argparse

from ._report import read_signatures
from ._stochastic import parse_property_map, signature_tile_size
from ._stochastic_result import check_stochastic_paths

__all__ = ["DEFAULT_SAMPLES", "add_stochastic_arguments", "stochastic_options"]

DEFAULT_SAMPLES = 100
#: (attribute, flag) of the options that only a stochastic run takes
_ONLY = (("samples", "--samples"), ("map", "--map"), ("random_seed", "--random-seed"),
         ("tile_size", "--tile-size"), ("workers", "--workers"),
         ("scheduler", "--scheduler"), ("histogram", "--histogram"),
         ("sample_table", "--sample-table"))


def add_stochastic_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``stochastic`` argument group to the ``simulate`` parser.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    """
    s = parser.add_argument_group(
        "stochastic", "with --stochastic, each material's conductivity is a random field: "
        "its intensity a Gaussian field of the material's mean_mean and mean_std at the "
        "RES (the signatures), correlated over the tile size (covariance exp(-(r/T)^2)), "
        "mapped by --map; k_eff of --samples realisations as mean, std, 95 % interval and "
        "Monte-Carlo standard error. Materials given in --conductivity stay fixed.")
    s.add_argument("--stochastic", default=None, metavar="SIG.csv",
                   help="the signatures (swa-imesh segment --signatures)")
    s.add_argument("--samples", type=int, default=None, metavar="N",
                   help=f"realisations to solve (default {DEFAULT_SAMPLES})")
    s.add_argument("--map", default=None, metavar="log-linear:A,B",
                   help="intensity to conductivity: log k = A + B * intensity (a Gaussian "
                        "intensity gives a log-normal k); required")
    s.add_argument("--tile-size", type=float, default=None, metavar="T",
                   help="the RES tile side: the correlation length, in voxels for a label "
                        "image, in the mesh's units for a mesh file (default: 2^scale from "
                        "the signatures' scale column, which swa-imesh segment writes)")
    s.add_argument("--random-seed", type=int, default=None, metavar="S",
                   help="seed of the fields (default 0): the same seed, the same samples "
                        "whatever the workers")
    s.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local Dask worker processes (default 1: solved in this process)")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a running Dask scheduler to solve on (tcp://host:8786)")
    s.add_argument("--histogram", default=None, metavar="FIGURE",
                   help="write the histogram of k_eff (.png, .pdf or .svg)")
    s.add_argument("--sample-table", default=None, metavar="CSV",
                   help="write k_eff of every sample (.csv)")


def stochastic_options(args: argparse.Namespace) -> dict | None:
    """Check the stochastic options before any work; None for a deterministic run.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``simulate`` arguments.

    Returns
    -------
    dict or None
        ``signatures`` (rows), ``samples``, ``property_map``, ``seed``, ``tile_size``,
        ``workers``, ``scheduler``, ``order``, ``histogram``, ``table``, ``memory``.

    Raises
    ------
    ValueError
        One sentence for the first problem found.
    """
    if args.stochastic is None:
        given = [flag for attr, flag in _ONLY if getattr(args, attr) is not None]
        if given:
            raise ValueError(f"{given[0]} applies to a stochastic run; add --stochastic "
                             "SIG.csv.")
        if not args.conductivity:
            raise ValueError("simulate needs --conductivity MATERIAL=K for every material "
                             "(or --stochastic SIG.csv to draw them from the signatures, "
                             "or --model fisher-kpp/drug with -D).")
        return None
    clash = [flag for flag, on in (
        ("--transient", args.transient is not None),
        ("--dirichlet/--neumann/--robin/--source",
         bool(args.dirichlet or args.neumann or args.robin or args.source)),
        ("--protocol periodic", args.protocol != "mixed"),
        ("--signatures", args.signatures), ("--report", args.report),
        ("--output", args.output), ("--max-aspect", args.max_aspect is not None),
        ("--adapt", str(args.adapt) not in ("auto", "0"))) if on]
    if clash:
        raise ValueError(f"--stochastic solves the mixed-boundary k_eff of each sample on "
                         f"one mesh; it does not combine with {clash[0]}.")
    if args.map is None:
        raise ValueError("--stochastic needs --map log-linear:A,B (log k = A + B * "
                         "intensity), the law from the signatures' intensities to k.")
    signatures = read_signatures(args.stochastic)
    tile_size = args.tile_size
    if tile_size is None:
        tile_size = signature_tile_size(signatures)
    if tile_size is None or not tile_size > 0:
        raise ValueError("--stochastic needs --tile-size T, the RES tile side (the "
                         "correlation length; swa-imesh segment --json prints tile_size), "
                         "a positive number, when the signatures have no scale column.")
    samples = DEFAULT_SAMPLES if args.samples is None else args.samples
    if samples < 2:
        raise ValueError(f"--samples must be 2 or more, not {samples}.")
    seed = 0 if args.random_seed is None else args.random_seed
    if seed < 0:
        raise ValueError(f"--random-seed must be 0 or more, not {seed}.")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be 1 or more, not {args.workers}.")
    if args.workers is not None and args.scheduler:
        raise ValueError("--workers starts local workers; with --scheduler the cluster has "
                         "its own: give one of them.")
    order = {"auto": 2, "1": 1, "2": 2}.get(str(args.order))   # auto: P2 (docs/stochastic)
    if order is None:
        raise ValueError(f"--order must be auto, 1 or 2, not {args.order}.")
    prop = parse_property_map(args.map)
    from ._budget import parse_memory

    memory = parse_memory(args.memory)
    check_stochastic_paths(args.sample_table, args.histogram, force=args.force)
    return {"signatures": signatures, "samples": samples,
            "property_map": prop, "seed": seed, "tile_size": float(tile_size),
            "workers": args.workers or 1, "scheduler": args.scheduler, "order": order,
            "histogram": args.histogram, "table": args.sample_table, "memory": memory}
