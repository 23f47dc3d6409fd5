"""Small helpers shared by the command-line sub-commands (no third-party imports)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ._timing import StepTimer  # the library's timer, re-used by the sub-commands

__all__ = ["StepTimer", "print_json", "to_jsonable", "parse_material_names"]


def to_jsonable(obj):
    """Convert numpy scalars/arrays and paths inside `obj` to plain JSON types."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())  # a numpy NaN must become null too
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def print_json(obj, file=None) -> None:
    """Print `obj` as one JSON object on a single line of stdout."""
    print(json.dumps(to_jsonable(obj)), file=file or sys.stdout)


def parse_material_names(items) -> dict[int, str]:
    """Parse ``["1=bone", "2=soft tissue"]`` into ``{1: "bone", 2: "soft tissue"}``.

    Examples
    --------
    >>> parse_material_names(["1=bone", " 2 = soft "])
    {1: 'bone', 2: 'soft'}
    """
    names: dict[int, str] = {}
    for item in items or ():
        key, sep, name = str(item).partition("=")
        try:
            material = int(key)
        except ValueError:
            material = -1
        if not sep or material < 0 or not name.strip() or '"' in name:
            raise ValueError(
                f"--material-names expects ID=NAME pairs with a non-negative integer ID "
                f"and a name without quotes, such as 1=bone; got {item!r}."
            )
        name = name.strip()
        twin = next((m for m, n in names.items() if n == name and m != material), None)
        if twin is not None:
            raise ValueError(
                f"materials {twin} and {material} share the name {name!r}; give each "
                "material its own name."
            )
        names[material] = name
    return names
