"""Small helpers shared by the command-line sub-commands (no third-party imports)."""

from __future__ import annotations

import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["StepTimer", "print_json", "to_jsonable", "check_writable"]


def to_jsonable(obj):
    """Convert numpy scalars/arrays and paths inside `obj` to plain JSON types."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def print_json(obj, file=None) -> None:
    """Print `obj` as one JSON object on a single line of stdout."""
    print(json.dumps(to_jsonable(obj)), file=file or sys.stdout)


class StepTimer:
    """Collects wall-clock seconds per named step: ``with timer("features"): ...``."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0


def check_writable(path, *, force: bool = False) -> Path:
    """Refuse to replace an existing file unless `force`; return the path.

    Raises
    ------
    FileExistsError
        If `path` exists and `force` is false.
    """
    p = Path(path)
    if p.exists() and not force:
        raise FileExistsError(
            f"{p} already exists; choose another output name or pass --force "
            "(force=True) to replace it."
        )
    if p.exists() and p.is_dir():
        raise IsADirectoryError(f"{p} is a directory; give a file name to write.")
    return p
