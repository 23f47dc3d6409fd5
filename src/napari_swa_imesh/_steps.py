"""Drive a step generator to its end: the library's ``f(...)`` is ``run_steps(f_steps(...))``.

Every long computation is written once as a generator that yields progress (for napari's
thread workers and the command line's progress lines) and returns its result; the plain
function runs it to the end.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any, TypeVar

__all__ = ["run_steps"]

T = TypeVar("T")


def run_steps(steps: Generator[Any, Any, T]) -> T:
    """Exhaust `steps`, discarding what it yields, and return its return value.

    Parameters
    ----------
    steps : generator
        A step generator (``segment_steps``, ``simulate_steps``, ...).

    Returns
    -------
    object
        The generator's return value (``StopIteration.value``).

    Examples
    --------
    >>> def count():
    ...     yield 1
    ...     yield 2
    ...     return "done"
    >>> run_steps(count())
    'done'
    """
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value
