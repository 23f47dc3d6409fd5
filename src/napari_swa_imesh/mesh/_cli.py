"""Sub-commands of ``swa-imesh`` for meshing: mesh, bounds."""

from __future__ import annotations


def add_commands(subparsers) -> None:
    """Register the meshing sub-commands on an argparse sub-parser group."""
