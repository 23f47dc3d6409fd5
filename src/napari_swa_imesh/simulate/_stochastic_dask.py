"""Blocks of Monte-Carlo samples on Dask: a local cluster, the user's scheduler, or here.

Each block is one task; results come back as they finish and are put in order by the
caller. A sample's random numbers depend only on the seed and its own index, so neither
the number of workers nor the blocks' placement changes a result.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

from .._dask_connect import connect_dask
from .._dask_logs import quiet_dask

__all__ = ["CONNECT_SECONDS", "run_blocks"]

CONNECT_SECONDS = 10


def run_blocks(fn: Callable, shared, blocks: Sequence, *, workers: int = 1,
               scheduler: str | None = None, client=None) -> Iterator[tuple[int, object]]:
    """``fn(shared, block)`` for every block: ``(index, result)`` as each finishes.

    Parameters
    ----------
    fn : callable
        A module-level function (it is pickled to the workers).
    shared : object
        The common input, sent once to every worker.
    blocks : sequence
        One task each.
    workers : int
        Without `scheduler` or `client`: 1 runs here, one block after the other; more
        starts a local cluster of that many single-threaded worker processes.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    client : distributed.Client, optional
        An existing client to submit to (it is left open).

    Yields
    ------
    (int, object)
        The block's index in `blocks` and ``fn``'s result.
    """
    if client is None and scheduler is None and workers <= 1:
        for i, block in enumerate(blocks):
            yield i, fn(shared, block)
        return
    if client is None:
        from .._extras import require

        require("distributed", purpose="solving the samples on several workers",
                alternative="or run them here with one worker")
    with quiet_dask():
        cluster = None
        own = client is None
        if own:
            client, cluster = connect_dask(scheduler, workers=workers,
                                           timeout=CONNECT_SECONDS)
        futures = []
        try:
            from distributed import as_completed

            data = client.scatter(shared, broadcast=True)
            futures = [client.submit(fn, data, block, pure=False) for block in blocks]
            index = {f.key: i for i, f in enumerate(futures)}
            for future in as_completed(futures):
                yield index[future.key], future.result()
        finally:                      # also when the consumer stops early (cancel)
            if futures:
                client.cancel(futures)
            if own:
                client.close()
                if cluster is not None:
                    cluster.close()
