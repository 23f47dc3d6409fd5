"""Wall-clock seconds per named step, for the library and the command line alike."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["StepTimer"]


class StepTimer:
    """Collects wall-clock seconds per named step: ``with timer("features"): ...``.

    A step timed twice adds up; ``seconds`` keeps the order in which steps first ended.

    Examples
    --------
    >>> timer = StepTimer()
    >>> with timer("fit"):
    ...     pass
    >>> with timer("fit"):
    ...     pass
    >>> list(timer.seconds), timer.seconds["fit"] >= 0.0
    (['fit'], True)
    """

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0
