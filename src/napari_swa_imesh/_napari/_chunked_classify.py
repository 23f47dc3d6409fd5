"""Applying a saved model to a lazy (Dask or multiscale) image layer, chunk by chunk.

The image is never loaded whole: :func:`~napari_swa_imesh.segmentation.predict_chunked`
plans chunks for the memory available and the labels are stored chunk by chunk into a
compressed in-memory Zarr store (labels compress to a few percent), shown as a lazy
Labels layer. :func:`chunked_steps` reports each finished chunk, and stops at the next
chunk when the run is cancelled.
"""

from __future__ import annotations

import threading
from collections.abc import Generator

import numpy as np

__all__ = ["lazy_level0", "chunked_steps", "CHUNKED_KEY"]

CHUNKED_KEY = "swa_imesh_chunked"        # Labels metadata: the plan of a chunked run


def lazy_level0(layer):
    """Level 0 of an image layer as a Dask array when its data are lazy, else None."""
    data = layer.data[0] if getattr(layer, "multiscale", False) else layer.data
    return data if type(data).__module__.startswith("dask.") else None


class _Cancelled(Exception):
    pass


def chunked_steps(data, model, *, memory: int | None = None, chunks=None
                  ) -> Generator[tuple[int, int, str], None, tuple]:
    """Label `data` (a Dask array) chunk by chunk; yield ``(done, total, message)``.

    `memory` and `chunks` go to :func:`~napari_swa_imesh.segmentation.predict_chunked`.

    Returns
    -------
    labels : dask.array.Array
        Backed by an in-memory compressed Zarr store of the computed labels.
    plan : dict
        As :func:`~napari_swa_imesh.segmentation.predict_chunked` returns it.
    """
    from .._extras import require

    require("dask", "zarr", purpose="classifying a lazy image chunk by chunk")
    import dask.array as da
    import zarr

    from ..segmentation import predict_chunked

    labels, plan = predict_chunked(model, data, memory=memory, chunks=chunks)
    total = int(np.prod(labels.numblocks))
    state = {"done": 0, "error": None}
    stop = threading.Event()
    lock = threading.Lock()

    def count(block):
        if stop.is_set():
            raise _Cancelled()
        with lock:
            state["done"] += 1
        return block

    store = zarr.create_array(zarr.storage.MemoryStore(), shape=labels.shape,
                              chunks=tuple(c[0] for c in labels.chunks), dtype=labels.dtype)
    counted = labels.map_blocks(count, meta=np.empty((0,) * labels.ndim, labels.dtype))

    def run():
        try:
            da.store(counted, store, lock=False, scheduler="threads",
                     num_workers=plan["workers"])
        except BaseException as exc:  # handed to the generator's thread
            state["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    yield 0, total, f"{total} chunks of {'x'.join(map(str, plan['chunks']))} voxels"
    try:
        while thread.is_alive():
            thread.join(0.2)
            yield state["done"], total, f"chunk {state['done']} of {total}"
    finally:
        stop.set()                          # a cancelled run stops at the next chunk
        thread.join()
    if state["error"] is not None:
        raise state["error"]
    return da.from_zarr(store), plan


def add_lazy_labels(viewer, image, labels, model, plan):
    """Show chunked labels over `image` as a lazy Labels layer (replacing an earlier one)."""
    from ._layers import AFFINE_KEY, block_affine, labels_colormap, material_palette

    names = {m.label: m.name for m in model.materials}
    colormap = labels_colormap(material_palette(names, {m.label: m.color
                                                        for m in model.materials}))
    name = f"{image.name} SWA labels"
    metadata = {CHUNKED_KEY: plan, "material_names": names, "swa_imesh_source": image.name,
                AFFINE_KEY: block_affine(image, 1)}
    if name in viewer.layers:
        viewer.layers.remove(name)
    return viewer.add_labels(labels, name=name, scale=image.scale, translate=image.translate,
                             affine=image.affine.affine_matrix, opacity=0.5,
                             colormap=colormap, metadata=metadata)
