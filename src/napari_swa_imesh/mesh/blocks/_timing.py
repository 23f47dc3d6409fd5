"""What each task of a block-wise run cost, measured inside the task.

Every task runs through :func:`timed`, which returns its result with the worker process's
id, the task's start and end (wall clock, seconds since the epoch) and the CPU seconds
the process spent on it. :func:`task_report` turns those into per-worker CPU and busy
time and a busy fraction per round (the time the workers ran tasks over the time the
round took, times the workers): figures that say whether the work scales (CPU per
voxel; the workers kept fed) however loaded the machine is, where wall time does not.
"""

from __future__ import annotations

import os
import time

__all__ = ["task_report", "timed"]


def timed(fn, *args):
    """``fn(*args)`` and ``(pid, start, stop, cpu seconds)`` of this call."""
    t0, c0 = time.time(), time.process_time()
    out = fn(*args)
    return out, (os.getpid(), t0, time.time(), time.process_time() - c0)


def task_report(rounds: dict[str, list[tuple]], n_workers: int) -> dict:
    """Per-worker and per-round figures of the tasks' timings.

    Parameters
    ----------
    rounds : dict of str to list of (pid, start, stop, cpu)
        The timings of each round's tasks, as :func:`timed` gives them.
    n_workers : int
        Workers that could run them (the busy fraction's denominator).

    Returns
    -------
    dict
        ``workers``: one entry per worker process (``pid``, ``tasks``, ``busy_s``,
        ``cpu_s``); ``rounds``: per round its ``span_s`` (first start to last stop),
        ``busy_s``, ``cpu_s`` and ``busy_fraction`` (``busy_s / (span_s * n_workers)``,
        1 when no worker ever waited).

    Examples
    --------
    >>> r = task_report({"mesh": [(1, 0.0, 2.0, 1.5), (2, 0.0, 1.0, 1.0)]}, 2)
    >>> r["rounds"]["mesh"]["busy_fraction"], [w["cpu_s"] for w in r["workers"]]
    (0.75, [1.5, 1.0])
    """
    workers: dict[int, dict] = {}
    out_rounds = {}
    for name, timings in rounds.items():
        if not timings:
            continue
        span = max(t[2] for t in timings) - min(t[1] for t in timings)
        busy = sum(t[2] - t[1] for t in timings)
        for pid, start, stop, cpu in timings:
            w = workers.setdefault(pid, {"pid": pid, "tasks": 0, "busy_s": 0.0, "cpu_s": 0.0})
            w["tasks"] += 1
            w["busy_s"] += stop - start
            w["cpu_s"] += cpu
        out_rounds[name] = {"span_s": span, "busy_s": busy,
                            "cpu_s": sum(t[3] for t in timings),
                            "busy_fraction": busy / (span * max(1, n_workers)) if span > 0
                            else 1.0}
    return {"n_workers": int(n_workers), "workers": list(workers.values()),
            "rounds": out_rounds}
