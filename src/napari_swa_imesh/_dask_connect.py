"""One way to reach Dask for every command that uses it (``batch``, block-wise ``mesh``,
stochastic ``simulate``): the user's scheduler, or a local cluster of single-threaded
worker processes that is refused in one sentence when it does not start."""

from __future__ import annotations

import logging
from collections.abc import Callable

__all__ = ["connect_dask", "first_line"]


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
