"""Quiet Dask logs for the commands that run on a cluster (``batch``, block-wise ``mesh``).

distributed logs worker restarts and the tracebacks of lost workers on its own; the
commands' progress lines and one sentence already say what happened.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["quiet_dask"]


@contextmanager
def quiet_dask() -> Iterator[None]:
    """Silence distributed's (and its event loop's) logs in this process while inside."""
    loggers = [logging.getLogger(n) for n in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)
