"""Sub-commands of ``swa-imesh`` for segmentation: res, segment, samples-from-truth, evaluate."""

from __future__ import annotations


def add_commands(subparsers) -> None:
    """Register the segmentation sub-commands on an argparse sub-parser group."""
