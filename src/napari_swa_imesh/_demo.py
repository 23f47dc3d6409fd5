"""``swa-imesh demo``: the whole pipeline on generated sample data."""

from __future__ import annotations


def add_command(subparsers) -> None:
    p = subparsers.add_parser("demo", help="segment (and mesh) the bundled sample data")
    p.set_defaults(func=run_demo)


def run_demo(args) -> int:
    raise NotImplementedError
