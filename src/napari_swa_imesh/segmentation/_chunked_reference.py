"""A saved reference (tile) model applied chunk by chunk: tiles aligned to the chunks.

Every feature of the reference method (moments, wavelet entropies, correlation lengths;
:mod:`._features`) is computed from the pixels of its own tile, and the tile grid starts
at index 0 as in memory. So a chunk whose sides are multiples of the tile side 2^j holds
whole tiles, needs no margin, and its labels are the whole image's (the features equal
to the last bits of their sums; tested for F1..F7). The last chunk along an axis takes
the remainder (the partial tiles at the far face, whose features come from their own
pixels in memory too); a remainder shorter than one tile joins the chunk before it, so
that every chunk is at least a tile long along each axis the image allows (the feature
code needs a tile to fit).

Memory: a worker holds one chunk at :data:`BYTES_PER_VOXEL` (the float64 copy, the
feature workers' temporaries, the labels; the worst case, F7 at scale 2 in 2-D, measured
84 bytes per voxel with tracemalloc).
"""

from __future__ import annotations

import os

import numpy as np

from ._features import feature_stack
from ._model import SWAModel, check_scale
from ._tiles import upsample_tiles

__all__ = ["predict_tiles_chunked", "tile_chunks", "plan_tiles", "BYTES_PER_VOXEL"]

BYTES_PER_VOXEL = 112     # per voxel of a chunk: features' peak (<= 84) + input + labels


def tile_chunks(shape, core, side: int) -> tuple[tuple[int, ...], ...]:
    """Dask chunks of `core` (multiples of the tile side `side`) per axis; the remainder
    is the last chunk, or joins the one before it when it is shorter than a tile.

    Examples
    --------
    >>> tile_chunks((20, 9, 30), (8, 8, 8), 4)   # 20 = 8+8+4; 9 = 8+1 joined; 30 = 8*3+6
    ((8, 8, 4), (9,), (8, 8, 8, 6))
    """
    out = []
    for n, c in zip(shape, core):
        sizes = [c] * (n // c)
        rest = n - c * len(sizes)
        if rest and sizes and rest < side:
            sizes[-1] += rest
        elif rest:
            sizes.append(rest)
        out.append(tuple(sizes))
    return tuple(out)


def plan_tiles(shape, model: SWAModel, memory: int, *, workers: int | None = None,
               reserved: int = 0) -> tuple[tuple[int, ...], int]:
    """Chunk shape (sides multiples of the tile side 2^scale) and worker threads for a
    budget: the largest near-cubic chunk that fits per worker, for the count of workers
    up to the cores with the most voxels per second (``workers`` when given).

    Raises
    ------
    ValueError
        When not even one tile per axis (doubled by a joined remainder) fits.
    """
    side = 1 << model.scale
    d = len(shape)
    counts = [workers] if workers else range(1, (os.cpu_count() or 1) + 1)
    best = None
    for w in counts:
        free = (memory - reserved) / w
        # the last chunk may hold a remainder of up to a tile more along each axis
        voxels = free / BYTES_PER_VOXEL
        c = int(voxels ** (1 / d)) - side
        c = c // side * side
        core = tuple(min(max(c, side), -(-n // side) * side) for n in shape)
        need = np.prod([min(k + side, n) for k, n in zip(core, shape)]) * BYTES_PER_VOXEL
        if c < side or need > free:
            continue
        if best is None or w * np.prod(core) > best[0]:
            best = (w * np.prod(core), core, w)
    if best is None:
        need = reserved + BYTES_PER_VOXEL * np.prod([min(2 * side, n) for n in shape])
        raise ValueError(
            f"a chunk of one tile of {side} px per axis needs about {need / 1e9:.2f} GB with "
            f"what this process holds, more than the budget of {memory / 1e9:.2f} GB; give "
            "more memory (--memory) or close other programs.")
    return best[1], best[2]


def predict_tiles_chunked(model: SWAModel, x, window, dtype, *, memory: int,
                          workers: int | None = None, reserved: int = 0, chunks=None,
                          check=None):
    """Labels of a large image by a fitted reference model, as a lazy Dask array (see
    :func:`~._chunked.predict_chunked`, which checks the arguments and calls this).

    Parameters
    ----------
    model : SWAModel
    x : dask.array.Array
        The image, checked for dimension and dtype.
    window : callable
        ``window(lo, hi)``: the image's pixels in that box, read inside a task.
    dtype : numpy.dtype
        Of the labels.
    memory, workers, reserved
        As for :func:`plan_tiles`.
    chunks : tuple of int, optional
        Chunk shape instead of the planned one, rounded down to multiples of the tile
        side (at least one tile).
    check : callable, optional
        Called with `x` before the graph is built (the NaN and contrast pass).

    Returns
    -------
    labels : dask.array.Array
    plan : dict
        ``chunks``, ``workers``, ``halo`` (0), ``bytes_per_voxel``, ``memory``.
    """
    import dask.array as da

    check_scale(model.scale, x.shape)
    side = 1 << model.scale
    if chunks is None:
        core, workers = plan_tiles(x.shape, model, memory, workers=workers,
                                   reserved=reserved)
    else:
        core = tuple(max(side, c // side * side) for c in chunks)
        workers = workers or 1
    if check is not None:
        check(x)
    template = da.empty(x.shape, chunks=tile_chunks(x.shape, core, side), dtype=np.uint8)
    labels = template.map_blocks(_labels_tiles, window=window, model=model, out=dtype,
                                 dtype=dtype, meta=np.empty((0,) * x.ndim, dtype))
    plan = {"chunks": core, "workers": workers, "halo": 0, "memory": memory,
            "bytes_per_voxel": BYTES_PER_VOXEL}
    return labels, plan


def _labels_tiles(_, window, model, out, block_info=None):
    """Labels (dtype `out`) of one chunk: its tiles' features, classified, each pixel its
    tile's label."""
    loc = block_info[0]["array-location"]
    block = window([a for a, _ in loc], [b for _, b in loc])
    feats, _, _ = feature_stack(block, model.scale, model.feature_set)
    labels = upsample_tiles(model.classify_features(feats), model.scale, block.shape)
    return labels.astype(out, copy=False)
