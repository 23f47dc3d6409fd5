"""A saved model applied to an image file, in memory or chunk by chunk, labels written.

What ``swa-imesh segment IMAGE --model M.npz -o LABELS`` does, and each task of ``swa-imesh
batch``: one function, so a cohort's labels equal one-by-one runs.

The chunked path (:mod:`._chunked`) is taken for a Zarr image or a Zarr output, when a
memory budget is given, or when the in-memory path would not fit the default budget; a
reference (tile) model works on chunks aligned to its tiles (:mod:`._chunked_reference`).
:func:`fit_apply` is ``segment IMAGE --samples S.json`` on that path: the model is fitted
on the boxes read from the store (:func:`~._chunked_fit.fit_chunked`), then applied as a
saved one. The labels go to a Zarr store chunk by chunk, or (another format) are gathered
whole (one or two bytes per voxel, counted in the budget). Without the ``[scale]`` extra
(dask, zarr) the chunked path is refused at its door (:func:`require_chunked`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._validation import label_dtype
from ._chunked import bytes_per_voxel, default_memory, predict_chunked
from ._chunked_fit import fit_chunked
from ._chunked_reference import BYTES_PER_VOXEL as TILE_BYTES_PER_VOXEL
from ._model import SWAModel
from ._recommended import RecommendedModel

__all__ = ["apply_model", "fit_apply", "wants_chunks", "material_volumes",
           "FIT_BYTES_PER_VOXEL"]

FIT_BYTES_PER_VOXEL = 56    # in-memory fit and prediction of the default method (issue 13)


def wants_chunks(image, output, model, *, memory: int | None = None,
                 budget: int | None = None) -> bool:
    """Whether :func:`apply_model` works chunk by chunk (see the module docstring).

    `memory` is a budget the user asked for (then always chunked); `budget` only sets
    what "too big for memory" means (default :func:`~._chunked.default_memory`). `model`
    None: fitting (:func:`fit_apply`), at :data:`FIT_BYTES_PER_VOXEL`.
    """
    from .._headers import Refused, load_npy
    from .._zarr_io import is_zarr

    if is_zarr(image) or is_zarr(output) or memory is not None:
        return True
    if not str(image).lower().endswith(".npy"):
        return False
    if not Path(image).is_file():
        raise FileNotFoundError(f"no image file at {image}; check the path.")
    try:
        lazy = load_npy(image, mmap_mode="r")      # the header: nothing is read
    except Refused:            # not a .npy file, or one of objects: said in full
        raise
    except Exception as exc:   # a damaged file
        raise ValueError(f"cannot read {image} as a .npy image: {exc}") from exc
    per_voxel = (FIT_BYTES_PER_VOXEL if model is None else TILE_BYTES_PER_VOXEL
                 if isinstance(model, SWAModel) else bytes_per_voxel(model, lazy.ndim))
    need = lazy.size * (per_voxel + lazy.dtype.itemsize + 4)
    return need > (default_memory() if budget is None else budget)


def require_chunked(image, output) -> None:
    """Raise :class:`~napari_swa_imesh._extras.MissingExtra` (naming ``[scale]``) unless
    the chunked path's packages are installed: dask, and zarr for a Zarr image or output.
    """
    from .._extras import require
    from .._zarr_io import is_zarr

    zarr = ("zarr",) if is_zarr(image) or is_zarr(output) else ()
    require("dask", *zarr, purpose="segmenting chunk by chunk (a Zarr image or output, "
            "--memory, or an image too big for memory)")


def material_volumes(counts: dict[int, int], spacing) -> dict[int, dict]:
    """Voxels and physical volume (voxel count x voxel size) of every material."""
    voxel = float(np.prod(spacing))
    return {int(k): {"voxels": int(n), "volume": n * voxel} for k, n in counts.items()}


def apply_model(image, model, output, *, memory: int | None = None,
                workers: int | None = None, force: bool = False,
                chunked: bool | None = None, scheduler: str = "threads") -> dict:
    """Segment the image file `image` with `model` and write the labels to `output`.

    Parameters
    ----------
    image : str or Path
        Any image :func:`~napari_swa_imesh.io.read_image` reads, a Zarr array or OME-Zarr
        image, or a ``.npy`` (memory-mapped on the chunked path).
    model : RecommendedModel or SWAModel
        A fitted or loaded model.
    output : str or Path
        Labels: ``.zarr`` (chunked) or a label format of
        :func:`~napari_swa_imesh.io.write_labels`; written through
        :func:`~napari_swa_imesh.io.atomic_write` (nothing is left on failure).
    memory : int, optional
        Budget in bytes (chunked; default :func:`~._chunked.default_memory`).
    workers : int, optional
        Threads of the chunked path (default: planned).
    force : bool
        Replace an existing output.
    chunked : bool, optional
        Force one path (default: :func:`wants_chunks`).
    scheduler : str
        Dask scheduler of the chunked path ("threads"; "sync" inside a busy worker).

    Returns
    -------
    dict
        ``output``, ``shape``, ``chunked``, ``plan`` (chunked), ``volumes`` per material,
        ``seconds``.

    Raises
    ------
    FileNotFoundError, FileExistsError, ValueError
        A missing image, an existing output without `force`, bad input (one sentence).
    """
    from .._zarr_io import open_lazy, write_zarr_to
    from ..io import (
        atomic_write,
        check_label_format,
        check_writable,
        image_suffix,
        is_store,
        label_array,
        read_affine,
        read_image,
        write_labels_to,
    )

    t0 = time.perf_counter()
    check_writable(output, force=force)
    if not is_store(output):
        check_label_format(output, label_array(np.zeros((1, 1), np.int64) + max(model.labels)))
    if chunked is None:
        chunked = wants_chunks(image, output, model, memory=memory)
    if chunked:
        require_chunked(image, output)
    affine = read_affine(image) if image_suffix(output) in (".nii", ".nii.gz") else None
    plan = None
    if not chunked:
        img, spacing = read_image(image)
        labels = label_array(model.predict(img))
    else:
        lazy, spacing = open_lazy(image)
        held = 0 if is_store(output) else lazy.size * np.dtype(
            label_dtype(model.labels)).itemsize
        import psutil

        reserved = psutil.Process().memory_info().rss + held
        lab, plan = predict_chunked(model, lazy, memory=memory, workers=workers,
                                    reserved=reserved, scheduler=scheduler)
        compute = {"scheduler": scheduler}
        if scheduler == "threads":
            compute["num_workers"] = plan["workers"]
        labels = None if is_store(output) else label_array(lab.compute(**compute))
    with atomic_write([output], force=force) as (tmp,):
        if labels is None:
            write_zarr_to(tmp, lab, spacing=spacing, **compute)
        else:
            check_label_format(output, labels)
            write_labels_to(tmp, labels, spacing=spacing, affine=affine)
    if labels is None:
        counts = _store_counts(output, model.labels, compute)
    else:
        values, n = np.unique(labels, return_counts=True)
        found = dict(zip(values.tolist(), n.tolist()))
        counts = {k: found.get(k, 0) for k in model.labels}
    return {"image": str(image), "output": str(output), "shape": list(lazy.shape if chunked
                                                                     else img.shape),
            "chunked": bool(chunked), "plan": plan,
            "volumes": material_volumes(counts, spacing),
            "seconds": time.perf_counter() - t0}


def fit_apply(image, samples, output, *, max_scale: int | None = None,
              memory: int | None = None, workers: int | None = None, force: bool = False,
              model_out=None, scheduler: str = "threads") -> dict:
    """Fit a recommended model on the sample boxes of a large image and segment it chunk
    by chunk, never loading the whole image.

    Parameters
    ----------
    image : str or Path
        A Zarr array, OME-Zarr image or ``.npy`` (any image :func:`apply_model` takes).
    samples : Samples
        Materials and boxes (checked against the image).
    output : str or Path
        Labels, as in :func:`apply_model`.
    max_scale : int, optional
        The model's largest scale (default: the suggested RES of the boxes, capped).
    memory, workers, force, scheduler
        As in :func:`apply_model`; the budget covers the fit too.
    model_out : str or Path, optional
        Save the fitted model here (``.npz``), after the labels are written.

    Returns
    -------
    dict
        :func:`apply_model`'s summary with ``fit``: seconds and the model's summary.
    """
    import psutil

    from .._zarr_io import open_lazy
    from ..io import check_writable

    t0 = time.perf_counter()
    require_chunked(image, output)
    check_writable(output, force=force)
    if model_out is not None:
        from ._model_base import check_model_path

        check_model_path(model_out)
        check_writable(model_out, force=force)
    lazy, spacing = open_lazy(image)
    model = fit_chunked(RecommendedModel(max_scale=max_scale), lazy, samples,
                        spacing=spacing, memory=default_memory() if memory is None else memory,
                        workers=workers, reserved=psutil.Process().memory_info().rss,
                        scheduler=scheduler)
    fitted = time.perf_counter() - t0
    summary = apply_model(image, model, output, memory=memory, workers=workers, force=force,
                          chunked=True, scheduler=scheduler)
    if model_out is not None:
        model.save(model_out, force=force)
    summary["fit"] = {"seconds": fitted, **model.summary()}
    summary["seconds"] += fitted
    return summary


def _store_counts(path, labels, compute) -> dict[int, int]:
    """Voxels of each label in a written store (one pass over its chunks)."""
    import dask

    from .._zarr_io import open_lazy

    arr, _ = open_lazy(path)
    sums = dask.compute(*[(arr == k).sum() for k in labels], **compute)
    return {int(k): int(n) for k, n in zip(labels, sums)}
