"""Reader for Zarr stores (plain arrays and OME-Zarr images): lazy Dask layers.

Nothing is loaded when the layer opens: napari reads the chunks of the slice it draws. An
OME-Zarr image with several resolution levels opens as a multiscale layer (napari draws
the level that suits the zoom); its ``scale`` is the voxel size of level 0. A store whose
values are integers opens as Labels when its name carries a label word (as for NIfTI) or
one chunk from its middle holds at most ``MAX_LABELS`` values (the NIfTI reader's rule,
:func:`~._reader.looks_like_labels`); else as an Image.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ._reader import looks_like_labels

__all__ = ["get_zarr_reader", "read_zarr", "LAZY_KEY"]

LAZY_KEY = "swa_imesh_lazy_source"       # the store a lazy layer reads (in its metadata)


def get_zarr_reader(path) -> Callable | None:
    """npe2 reader command: a reader for one Zarr store, else None."""
    from .._zarr_io import is_zarr

    if isinstance(path, (list, tuple)) or not is_zarr(str(path).rstrip("/")):
        return None
    return read_zarr


def _middle_chunk(arr) -> np.ndarray:
    """One chunk of a Dask array, from its middle (the corner is often background)."""
    index = tuple(n // 2 for n in arr.numblocks)
    return np.asarray(arr.blocks[index])


def read_zarr(path) -> list[tuple]:
    """Read a Zarr store as a lazy (multiscale, if it has levels) Image or Labels layer."""
    from .._zarr_io import open_levels

    p = Path(str(path).rstrip("/"))
    levels, spacing = open_levels(p)
    name = p.name
    for suffix in (".zarr", ".ome"):
        name = name.removesuffix(suffix)
    multiscale = len(levels) > 1
    kwargs = {"name": name, "scale": spacing, "multiscale": multiscale,
              "metadata": {LAZY_KEY: str(p)}}
    data = levels if multiscale else levels[0]
    labels = levels[0].dtype.kind in "iub" and looks_like_labels(
        _middle_chunk(levels[-1]), name)
    return [(data, kwargs, "labels" if labels else "image")]
