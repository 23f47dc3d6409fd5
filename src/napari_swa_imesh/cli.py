"""The ``swa-imesh`` command line: one sub-command per step of the pipeline.

Every sub-command returns 0 on success; bad input is reported as one sentence on
stderr with exit status 2 (never a traceback).
"""

from __future__ import annotations

import argparse
import re
import sys
import warnings

from .mesh._cli import add_commands as add_mesh_commands
from .segmentation._cli import add_commands as add_segmentation_commands
from .simulate._cli import add_commands as add_simulate_commands

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="swa-imesh",
        description="Image -> SWA segmentation -> IMESH finite-element mesh.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_segmentation_commands(sub)
    add_mesh_commands(sub)
    add_simulate_commands(sub)
    from ._demo import add_command as add_demo_command

    add_demo_command(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    prefix = f"swa-imesh {args.command}"

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"{prefix}: warning: {message}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.simplefilter("always", UserWarning)
        warnings.showwarning = show
        try:
            return int(args.func(args) or 0)
        except MemoryError as exc:
            # numpy says "Unable to allocate 8.00 GiB for an array with shape ..."
            size = re.search(r"allocate ([0-9.]+ [KMGTP]?i?B)", str(exc))
            what = f" (an allocation of {size.group(1)} failed)" if size else ""
            print(f"{prefix}: error: ran out of memory{what}; crop the image, coarsen "
                  "(downsample) it, or work on a sub-volume, or run on a machine with more "
                  "memory.", file=sys.stderr)
            return 2
        except (ValueError, TypeError, OSError, KeyError) as exc:
            msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            print(f"{prefix}: error: {msg}", file=sys.stderr)
            return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
