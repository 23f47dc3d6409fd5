"""One way to reach Dask for every command that uses it (``batch``, block-wise ``mesh``,
stochastic ``simulate``): the user's scheduler, or a local cluster of single-threaded
worker processes that is refused in one sentence when it does not start. The public entry
point that passes the connection's parameters on (``pipeline.connect``) documents them with
:func:`connect_dask`'s own entries (:func:`with_dask_parameters`), so they are described
once."""

from __future__ import annotations

import inspect
import logging
import re
from collections.abc import Callable
from typing import TypeVar

__all__ = ["connect_dask", "first_line", "with_dask_parameters"]

_F = TypeVar("_F", bound=Callable)
_MARK = re.compile(r"^( *)<connect_dask: ([\w, ]+)>$", re.MULTILINE)


def first_line(error: str) -> str:
    """The first line of an error (dask's KilledWorker and the like run on)."""
    lines = [line for line in str(error).splitlines() if line.strip()]
    return lines[0].strip() if lines else "the task failed without a message"


def connect_dask(scheduler: str | None, *, workers: int, memory: int | str | None = None,
                 timeout: float = 10, preload: Callable[[], None] | None = None):
    """``(client, cluster)``: a client on `scheduler` (cluster None), else on a new
    ``LocalCluster`` the caller closes.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    workers : int
        Single-threaded worker processes of the local cluster.
    memory : int or str, optional
        Memory limit of each local worker (bytes, or Dask's ``"4GB"``); Dask's ``"auto"``
        when not given.
    timeout : float
        Seconds a scheduler has to answer.
    preload : callable, optional
        Run on every local worker once it has started (imports belong to starting the
        cluster, not to the first task).

    Returns
    -------
    tuple
        ``(distributed.Client, distributed.LocalCluster or None)``.

    Raises
    ------
    ValueError
        When the scheduler does not answer within `timeout`, or a local worker dies
        while starting.
    """
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=f"{timeout:g}s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise ValueError(f"no Dask scheduler answers at {scheduler} within {timeout:g} s "
                             f"({type(exc).__name__}); start one (`dask scheduler`) or leave "
                             "--scheduler out to use a local cluster.") from exc
    import dask

    # each task is a few long numpy calls: the workers' stack sampler (every 10 ms, under
    # the GIL) would only slow them down
    cluster = None
    try:
        with dask.config.set({"distributed.worker.profile.enabled": False}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   memory_limit=memory or "auto", dashboard_address=None,
                                   silence_logs=logging.CRITICAL)
        client = Client(cluster)
        if preload is not None:
            client.run(preload)
    except Exception as exc:    # "Nanny failed to start", a worker killed while starting
        if cluster is not None:
            cluster.close()
        raise ValueError(
            f"the local Dask cluster of {workers} worker(s) did not start (a worker process "
            f"died while starting: {type(exc).__name__}: {first_line(str(exc))}); check the "
            "memory left (--memory), try fewer --workers, or give --scheduler.") from exc
    return client, cluster


def _parameter_entries() -> dict[str, str]:
    """:func:`connect_dask`'s numpydoc parameter entries by name (dedented)."""
    lines = inspect.cleandoc(connect_dask.__doc__ or "").splitlines()
    entries: dict[str, list[str]] = {}
    for line in lines[lines.index("Parameters") + 2:]:
        if not line.strip():
            break                                   # the section ends at a blank line
        if not line.startswith(" "):
            entries[line.split(" :")[0]] = [line]
        else:
            entries[next(reversed(entries))].append(line)
    return {name: "\n".join(entry) for name, entry in entries.items()}


def with_dask_parameters(func: _F) -> _F:
    """Fill the line ``<connect_dask: scheduler, workers>`` of `func`'s docstring with
    those parameters' entries in :func:`connect_dask`'s, so an entry point that passes
    them on (``pipeline.connect``) documents them in full from one description."""
    if func.__doc__ is None or connect_dask.__doc__ is None:
        return func                                 # python -OO: no docstrings
    doc = inspect.cleandoc(func.__doc__)
    mark = _MARK.search(doc)
    if mark is None:
        raise ValueError(f"{func.__qualname__}'s docstring has no <connect_dask: ...> line")
    entries = _parameter_entries()
    names = [name.strip() for name in mark.group(2).split(",")]
    stray = [name for name in names if name not in entries]
    if stray:
        raise ValueError(f"{func.__qualname__}'s docstring names {', '.join(stray)}, which "
                         f"connect_dask does not take; name only {', '.join(entries)}")
    text = "\n".join(entries[name] for name in names)
    func.__doc__ = doc[:mark.start()] + text + doc[mark.end():]
    return func
