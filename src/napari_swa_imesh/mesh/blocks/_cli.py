"""The block-wise path of ``swa-imesh mesh``: ``-o OUT.pvtu`` (or ``--workers``,
``--scheduler``, ``--block``, ``--memory`` with ``.pvtu``/``.xdmf``) meshes the volume
block by block on Dask (:func:`~._run.mesh_blocks`).

:func:`add_commands` registers ``mesh`` and ``bounds`` as ``mesh._cli`` does, then adds
the block options to ``mesh`` and routes a block-wise run here, so ``mesh._cli`` is not
edited (``cli.COMMAND_MODULES`` names this module for those commands)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..._dask_logs import quiet_dask
from ..formats._registry import PVTU

__all__ = ["add_block_arguments", "add_commands", "run_blocks", "uses_blocks"]


def add_commands(subparsers) -> None:
    """``mesh._cli.add_commands``, with the block-wise options and path on ``mesh``."""
    from .._cli import add_commands as add_mesh_commands
    from .._cli import parse_material_names

    add_mesh_commands(subparsers)
    p = subparsers.choices["mesh"]
    add_block_arguments(p)
    in_memory = p.get_default("func")

    def run(args: argparse.Namespace) -> int:
        if uses_blocks(args):
            return run_blocks(args, parse_material_names(args.material_names))
        return in_memory(args)

    p.set_defaults(func=run)

#: options of the in-memory path the block path does not take, with their defaults
_NOT_HERE = {"method": "template", "msh_ascii": False,
             "index_space": False, "full_check": False, "facet_groups": "all"}


def add_block_arguments(p: argparse.ArgumentParser) -> None:
    """The block-wise options of ``mesh``."""
    g = p.add_argument_group("block-wise meshing (output .pvtu, or .xdmf with any of these)")
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local Dask worker processes (default 2; 0: no Dask, one process)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:8786) instead of local workers")
    g.add_argument("--memory", default=None, metavar="SIZE",
                   help="memory per worker, e.g. 4GB: picks the block size (default 2GB)")
    g.add_argument("--block", type=int, default=None, metavar="B",
                   help="block side in voxels, a power of two (default: from --memory)")


def uses_blocks(args: argparse.Namespace) -> bool:
    """Whether the command asks for the block-wise path."""
    return (Path(args.output).suffix.lower() == PVTU
            or any(getattr(args, k, None) is not None
                   for k in ("workers", "scheduler", "memory", "block")))


def run_blocks(args: argparse.Namespace, names: dict[int, str]) -> int:
    """Run the block-wise ``mesh`` (`names` parsed from ``--material-names``); exit
    status 0 (errors raise ValueError & co)."""
    from ..model._memory import format_bytes, parse_memory_size
    from ._run import BLOCK_SUFFIXES, mesh_blocks

    if Path(args.output).suffix.lower() not in BLOCK_SUFFIXES:
        raise ValueError(f"block-wise meshing writes {' or '.join(BLOCK_SUFFIXES)}; got "
                         f"{Path(args.output).name!r}.")
    used = [k for k, v in _NOT_HERE.items() if getattr(args, k, v) != v]
    if used:
        raise ValueError(f"--{used[0].replace('_', '-')} is not available for block-wise "
                         "meshing (template method only); leave it "
                         "out, or mesh in memory with another output suffix.")
    if args.order not in ("1", "2"):
        raise ValueError(f"--order must be 1 or 2, not {args.order!r}.")
    memory = parse_memory_size(args.memory) if args.memory else None
    if args.workers is not None and args.scheduler:
        raise ValueError("give --workers or --scheduler, not both: a scheduler has its own "
                         "workers.")
    workers = 2 if args.workers is None else args.workers
    quiet = args.json

    def progress(stage, done, total):
        if not quiet:
            print(f"\r{stage}: {done}/{total} blocks", end="\n" if done == total else "",
                  file=sys.stderr, flush=True)

    with quiet_dask():
        report = mesh_blocks(args.labels, args.output, block=args.block, memory=memory,
                             workers=workers, scheduler=args.scheduler,
                             exclude=tuple(args.exclude), spacing=args.spacing,
                             material_names=names, subdivide=not args.no_subdivide,
                             max_aspect=args.max_aspect, max_size=args.max_size,
                             refine=args.refine, order=int(args.order),
                             periodic=args.periodic, coarsen=args.coarsen,
                             force=args.force, progress=progress)
    if args.json:
        print(json.dumps(report))   # plain ints, floats, strings and lists
    else:
        vols = ", ".join(f"{m}: {v:g}" for m, v in report["volumes"].items())
        cells = report["lattice"]["cells_per_voxel"]
        unit = "voxels" if set(cells) == {1} else f"lattice cells, {cells} per voxel"
        print(f"wrote {report['output']} ({report['pieces']} pieces in "
              f"{report['pieces_folder']}, blocks of {report['block']}^{len(report['shape'])}"
              f" {unit}): {report['n_elements']} elements, worst radius-to-edge "
              f"{report['worst_ratio']:.4f} (bound {report['quality_bound']:.4f})"
              + ("; 10-node elements" if report["order"] == 2 and len(report["shape"]) == 3
                 else "; 6-node elements" if report["order"] == 2 else "")
              + ("; box faces periodic" if report["periodic"] else "")
              + f"; seams conforming; volumes exact ({vols})"
              + ("" if memory is None else f"; {format_bytes(memory)} per worker"))
    return 0
