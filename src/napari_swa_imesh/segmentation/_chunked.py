"""A saved recommended model applied chunk by chunk on Dask: images larger than memory.

Every step of :meth:`RecommendedModel.predict` but the bias field is local, so each chunk
is classified with a margin of :func:`halo` px (clipped at the image's own faces: what
``dask.array.map_overlap`` with ``boundary="none"`` gives), the exact reach of one label
(axes below are per axis):

* the features of level j see 2^j px (window half-width 2^(j-1), plus the Haar details
  of level j-1, 2^(j-1) px);
* refining level j looks 2^(j-1) px around for a second label: from the coarse level J
  down to the finest f that adds 2^J - 2^f px to the 2^J of level J's features;
* the Potts MRF: a pixel is active if it is unsure or touches another label (1 px), grown
  by one (2 px), then each of the :data:`~._mrf.SWEEPS` sweeps reads the face neighbours
  (1 px each): 2 + SWEEPS px.

Inside the margin a chunk's labels are the whole image's (tested on tiny chunks). Each
task reads its own padded window from the store's chunks: ``map_overlap`` itself keeps
every input chunk alive while a neighbour still needs a slice of it (the slices are
views), which held a slab of the volume (4 GB for a 2.5 GB budget at 1024^3); windows
cost some re-reading of the margins instead, and memory is one padded chunk per worker.

The global steps: the intensity standardisation is the model's own (offset and scale fixed
at training), so it is pointwise; the bias field is estimated as in memory, on a
downsampled copy (the strided copy the in-memory path labels when the finest level is the
pixel value, else block sums of a chunked labelling pass at the finest level), and each
chunk evaluates the field's linear interpolation on its own voxels only.

Memory: a worker holds one padded chunk at :func:`bytes_per_voxel` (the worst case: every
voxel active in the MRF); :func:`plan_chunks` picks the largest chunk that the budget
allows per worker, and refuses when even a small one does not fit.
"""

from __future__ import annotations

import os

import numpy as np

from .._validation import label_dtype
from ._bias import (
    LOCAL_WINDOW,
    coarse_bias_field,
    field_terms,
    grid_factor,
    upsample_linear,
    upsample_linear_at,
)
from ._chunked_reference import predict_tiles_chunked
from ._classifiers import PREDICT_BATCH
from ._model import SWAModel
from ._mrf import SWEEPS, potts_mean_field
from ._recommended import BIAS_ROUNDS, FIELD_GRID, RecommendedModel
from ._tiles import block_counts, block_mean, block_sum

__all__ = ["halo", "bytes_per_voxel", "batch_bytes", "plan_chunks", "predict_chunked",
           "parse_memory", "default_memory", "MRF_REACH", "MIN_CORE", "bias_round",
           "strided_copy", "refuse_flat", "Window", "smallest_dtype"]

MRF_REACH = 2 + SWEEPS   # active set (1 px), grown by one (1 px), one px per sweep
MIN_CORE = 16            # smallest chunk side worth the margin around it
MEMORY_FRACTION = 0.5    # default budget: this share of the memory available now


def halo(model: RecommendedModel) -> int:
    """Margin (px per side) that makes a chunk's labels equal the whole image's.

    Examples
    --------
    >>> m = RecommendedModel()
    >>> m.scale, m.finest_scale = 3, 1
    >>> halo(m)        # 2^3 (features) + 2^3 - 2^1 (refinement) + 7 (MRF)
    21
    """
    j, f = model.scale, model.finest_scale
    reach = 0 if j == 0 else (1 << (j + 1)) - (1 << f)
    return reach + (MRF_REACH if model.beta > 0 else 0)


def bytes_per_voxel(model: RecommendedModel, ndim: int) -> int:
    """Working memory per voxel of a padded chunk (the larger of the feature and MRF steps).

    Features: the float32 stack, the Haar energies, float64 running sums and filter
    temporaries, the log-likelihoods. MRF, per voxel when all are active (noise at the
    pixel level): indices, likelihoods, probabilities, neighbour columns and temporaries.
    Add :func:`batch_bytes` once per block. Checked against tracemalloc peaks in the tests.
    """
    k, f = len(model.labels), _n_features(model)
    features = 4 * f + 4 * model.scale + 40 + 4 * k
    mrf = 24 * k + 24 * ndim + 24
    return int(max(features, mrf)) + 4 + 4 + 1       # + the padded input, work, labels


def batch_bytes(model: RecommendedModel, n_voxels: int) -> int:
    """Temporaries of the classifier's batches (rows of features, bounded per batch)."""
    return 16 * _n_features(model) * min(int(n_voxels), PREDICT_BATCH)


def _n_features(model) -> int:
    return len(model.levels[model.scale].offset_) if model.levels else 1


def parse_memory(text) -> int:
    """Bytes of a budget such as ``"2GB"``, ``"1.5GiB"``, ``"500MB"`` or a number of bytes.

    Raises
    ------
    ValueError
        For anything else, or a budget of zero or less.
    """
    from .._extras import require

    require("dask", purpose="a memory budget (segmenting chunk by chunk)")
    from dask.utils import parse_bytes

    try:
        value = int(parse_bytes(text))
    except (ValueError, TypeError) as exc:
        raise ValueError(f"cannot read {text!r} as an amount of memory; give e.g. 2GB, "
                         "1.5GiB or 500MB.") from exc
    if value <= 0:
        raise ValueError(f"the memory budget must be more than 0; got {text!r}.")
    return value


def default_memory() -> int:
    """:data:`MEMORY_FRACTION` of the memory available now (psutil)."""
    import psutil

    return int(MEMORY_FRACTION * psutil.virtual_memory().available)


def plan_chunks(shape, model: RecommendedModel, memory: int, *, workers: int | None = None,
                reserved: int = 0, multiple: int = 1) -> tuple[tuple[int, ...], int]:
    """Chunk shape (without margin) and number of worker threads for a memory budget.

    For each worker count up to the cores, the largest chunk whose padded block fits the
    budget per worker; the count whose chunks waste the least time on margins per worker
    wins (``workers / ((c + 2h) / c)^d``).

    Parameters
    ----------
    shape : tuple of int
    model : RecommendedModel
    memory : int
        Budget in bytes for the whole process.
    workers : int, optional
        Fix the number of threads (default: choose up to ``os.cpu_count()``).
    reserved : int
        Bytes of the budget already taken (the process itself, an output held whole).
    multiple : int
        Chunk sides are multiples of this (the bias field's grid cells).

    Returns
    -------
    chunk : tuple of int
        Chunk shape, without its margin.
    workers : int
        Number of worker threads.

    Raises
    ------
    ValueError
        When not even a chunk of :data:`MIN_CORE` px per axis (or the whole image, if
        smaller) fits the budget.
    """
    d, h = len(shape), halo(model)
    bpv = bytes_per_voxel(model, d)
    batch = batch_bytes(model, int(np.prod(shape)))
    counts = [workers] if workers else range(1, (os.cpu_count() or 1) + 1)
    best = None
    for w in counts:
        free = (memory - reserved) / w - batch
        core = _largest_core(shape, h, bpv, free, multiple)
        if core is None:
            continue
        waste = np.prod([(c + 2 * h * (c < n)) / c for c, n in zip(core, shape)])
        score = w / waste
        if best is None or score > best[0]:
            best = (score, core, w)
    if best is None:
        small = tuple(min(n, max(MIN_CORE, multiple)) for n in shape)
        need = reserved + batch + bpv * int(np.prod([c + 2 * h * (c < n) for c, n in
                                                     zip(small, shape)]))
        raise ValueError(
            f"a chunk of {'x'.join(map(str, small))} voxels with its margin of {h} px needs "
            f"about {need / 1e9:.2f} GB with what this process holds, more than the budget "
            f"of {memory / 1e9:.2f} GB; give more memory (--memory) or close other programs.")
    return best[1], best[2]


def _largest_core(shape, h: int, bpv: int, free: float, multiple: int):
    """Largest near-cubic chunk whose padded block holds `free` bytes, or None."""
    if free <= 0:
        return None
    d = len(shape)
    fixed = [False] * d
    core = list(shape)
    for _ in range(d):                       # axes shorter than the side are taken whole
        grow = [i for i in range(d) if not fixed[i]]
        if not grow:
            break
        whole = np.prod([shape[i] for i in range(d) if fixed[i]] or [1])
        side = int((free / bpv / whole) ** (1 / len(grow))) - 2 * h
        for i in grow:
            core[i] = min(shape[i], side)
        short = [i for i in grow if shape[i] <= side]
        if not short:
            break
        for i in short:
            fixed[i] = True
    core = [c if c == n else c // multiple * multiple for c, n in zip(core, shape)]
    if min(c for c in core) < 1 or any(c < min(n, max(MIN_CORE, h, multiple))
                                       for c, n in zip(core, shape)):
        return None
    padded = np.prod([c + 2 * h * (c < n) for c, n in zip(core, shape)])
    return tuple(core) if padded * bpv <= free else None


def predict_chunked(model: RecommendedModel, image, *, memory: int | None = None,
                    workers: int | None = None, reserved: int = 0, chunks=None,
                    **compute):
    """Labels of a large image by a fitted model, as a lazy Dask array.

    A reference (tile) model works on chunks aligned to its tiles, without margin
    (:mod:`._chunked_reference`); the rest of this docstring is about the recommended one.

    Parameters
    ----------
    model : RecommendedModel or SWAModel
        Fitted or loaded (:func:`~._model_io.load_model`).
    image : (M, N[, P]) dask.array.Array or array_like
        Grey-level image (e.g. from :func:`napari_swa_imesh._zarr_io.open_lazy`).
    memory : int, optional
        Budget in bytes (default :func:`default_memory`).
    workers : int, optional
        Threads (default: chosen by :func:`plan_chunks`).
    reserved : int
        Bytes of the budget already taken.
    chunks : tuple of int, optional
        Chunk shape to use instead of the planned one (tests use tiny chunks).
    **compute
        Passed to ``dask.compute`` for the global steps (``scheduler``...).

    Returns
    -------
    labels : dask.array.Array
        Labels in the smallest integer type that holds them, with the planned chunks; computing it
        chunk by chunk (``store``) holds one padded chunk per worker.
    plan : dict
        ``chunks``, ``workers``, ``halo``, ``bytes_per_voxel``, ``memory``.

    Raises
    ------
    ValueError
        A dimensionality the model was not fitted for, an image of one
        value or NaN/infinity (found by a pass over the chunks before any labelling), a
        budget too small for one chunk.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> from ._samples import Samples
    >>> img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(4, 1, (32, 16))], 1)
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [32, 12]},
    ...                                  {"label": 2, "start": [0, 20], "stop": [32, 32]}]})
    >>> m = RecommendedModel(max_scale=1, bias_correction=False).fit(img, s)
    >>> lab, plan = predict_chunked(m, img, chunks=(16, 16))
    >>> bool((lab.compute() == m.predict(img)).all())
    True
    """
    import dask.array as da

    if not isinstance(model, (RecommendedModel, SWAModel)):
        raise TypeError(f"model must be a RecommendedModel or SWAModel; got "
                        f"{type(model).__name__}.")
    if not model.materials:
        raise ValueError("this model is not fitted; call fit() or load a saved model.")
    x = image if isinstance(image, da.Array) else da.from_array(np.asarray(image))
    if x.ndim != model.ndim:
        raise ValueError(f"the model was fitted on {model.ndim}-D images; got a {x.ndim}-D "
                         "image.")
    if x.dtype.kind not in "biuf":
        raise TypeError(f"image must hold real numbers; got dtype {x.dtype}.")
    memory = default_memory() if memory is None else int(memory)
    if isinstance(model, SWAModel):
        # tiles are local: chunks aligned to them need no margin and no global step
        window = Window(image if isinstance(image, np.ndarray) else x)
        return predict_tiles_chunked(model, x, window, smallest_dtype(model.labels),
                                     memory=memory, workers=workers,
                                     reserved=reserved, chunks=chunks,
                                     check=lambda arr: _check_contrast(arr, compute))
    f = model.finest_scale
    multiple = grid_factor(x.shape) if model.bias_correction and f > 0 else 1
    if chunks is None:
        core, workers = plan_chunks(x.shape, model, memory, workers=workers,
                                    reserved=reserved, multiple=multiple)
    else:
        # the bias sums need whole grid cells in every chunk
        core = tuple(min(n, max(multiple, c // multiple * multiple))
                     for c, n in zip(chunks, x.shape))
        workers = workers or 1
    if compute.get("scheduler", "threads") == "threads":
        compute = {**compute, "num_workers": compute.get("num_workers", workers)}
    h = halo(model)
    plan = {"chunks": core, "workers": workers, "halo": h, "memory": memory,
            "bytes_per_voxel": bytes_per_voxel(model, x.ndim)}
    field = _bias_small(model, x, f, core, compute) if model.bias_correction else None
    if field is None:
        _check_contrast(x, compute)
    window = Window(image if isinstance(image, np.ndarray) else x)
    dtype = smallest_dtype(model.labels)
    labels = _template(x.shape, core).map_blocks(
        _labels_direct, window=window, model=model, field=field, margin=h, dtype=dtype,
        meta=np.empty((0,) * x.ndim, dtype))
    return labels, plan


class Window:
    """Reads a padded window of the image inside a task, from the store's own chunks (a
    Dask array is computed there, synchronously: only the chunks the window touches)."""

    def __init__(self, source):
        self.source = source

    def __call__(self, lo, hi) -> np.ndarray:
        part = self.source[tuple(slice(a, b) for a, b in zip(lo, hi))]
        if hasattr(part, "compute"):
            part = part.compute(scheduler="sync")
        return np.asarray(part)


def _template(shape, core):
    """A cheap array whose blocks are the chunks (each task reads its own window)."""
    import dask.array as da

    return da.empty(shape, chunks=core, dtype=np.uint8)


def _padded(block_info, margin: int):
    """(lo, hi) of the chunk grown by `margin` and clipped at the image's faces, and the
    slices of the chunk inside that window."""
    loc, shape = block_info[0]["array-location"], block_info[0]["shape"]
    lo = [max(0, a - margin) for a, _ in loc]
    hi = [min(n, b + margin) for (_, b), n in zip(loc, shape)]
    inner = tuple(slice(a - low, b - low) for (a, b), low in zip(loc, lo))
    return lo, hi, inner, shape


def _work_window(window, model, field, lo, hi, shape) -> np.ndarray:
    """Standardised (and bias-corrected) float32 window, as the in-memory path makes it
    (NaN and infinity were refused by the global minimum and maximum)."""
    work = model._standardised(window(lo, hi))
    if field is not None:
        work /= upsample_linear_at(field, shape, [np.arange(a, b) for a, b in zip(lo, hi)])
    return work


def _labels_direct(_, window, model, field, margin, block_info=None):
    """Labels of one chunk: its window with the margin, classified, the chunk cut out
    (what ``map_overlap`` with ``boundary="none"`` computes, without holding neighbours)."""
    lo, hi, inner, shape = _padded(block_info, margin)
    return _labels_block(_work_window(window, model, field, lo, hi, shape), model)[inner]


def _check_contrast(x, compute) -> None:
    import dask

    lo, hi = dask.compute(x.min(), x.max(), **compute)
    refuse_flat(lo, hi)


def refuse_flat(lo, hi) -> None:
    """Refuse an image whose minimum `lo` and maximum `hi` say NaN, infinity or one value."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError("the image has NaN or infinite values; fill or mask them first "
                         "(e.g. numpy.nan_to_num).")
    if lo == hi:
        raise ValueError(f"the image holds one value everywhere ({float(lo):g}); there is "
                         "nothing to segment. Check that the right file or channel was given.")


def _labels_block(work, model):
    ll, _ = model._classify_standardised(work)
    cls = potts_mean_field(ll, model.beta, labels_only=True)
    return model._class_values()[cls].astype(smallest_dtype(model.labels), copy=False)


def smallest_dtype(labels) -> np.dtype:
    """The dtype labels are written in (the policy's file side, as ``io.label_array``)."""
    return label_dtype(list(labels) + [0], smallest=True)


def _bias_small(model, x, f, core, compute) -> np.ndarray:
    """The field on a small grid whose linear interpolation to ``x.shape`` is the
    in-memory field (both rounds of :data:`BIAS_ROUNDS`)."""
    import dask

    sub = None
    if f == 0:
        # the in-memory path labels a strided copy: the same copy, read chunk by chunk
        sub, lo, hi = dask.compute(strided_copy(x), x.min(), x.max(), **compute)
    else:
        lo, hi = dask.compute(x.min(), x.max(), **compute)
    refuse_flat(lo, hi)
    small = None
    for _ in range(BIAS_ROUNDS):
        small = bias_round(model, x, core, small, sub=sub, **compute)
    return small


def strided_copy(x):
    """The every-k-th-voxel copy (lazy) that the field of a pixel-value level labels."""
    step = max(1, min(x.shape) // FIELD_GRID)
    return x[tuple(slice(None, None, step) for _ in x.shape)]


def bias_round(model: RecommendedModel, x, core, small: np.ndarray | None, *,
               sub: np.ndarray | None = None, **compute) -> np.ndarray:
    """One estimate of the bias field of the image `x` (Dask), as a small grid whose
    linear interpolation to ``x.shape`` is :meth:`RecommendedModel._bias_field` of the
    image corrected by `small` (None: uncorrected), labelled by the finest level.

    Parameters
    ----------
    core : tuple of int
        Chunks of the labelling pass (sides multiples of the grid cell).
    sub : ndarray, optional
        :func:`strided_copy` already read (finest level 0).
    """
    shape, f = x.shape, model.finest_scale
    if f == 0:
        step = max(1, min(shape) // FIELD_GRID)
        if sub is None:
            sub = strided_copy(x).compute(**compute)
        base = model._standardised(np.asarray(sub))
        idx = [np.arange(0, n, step) for n in shape]
        work = base if small is None else base / upsample_linear_at(small, shape, idx)
        num, den = field_terms(base, work, model._predict_level(work, 0), model.class_means)
        factor = grid_factor(base.shape)
        coarse = coarse_bias_field(block_mean(num, factor), block_mean(den, factor))
        return coarse if step == 1 else upsample_linear(coarse, base.shape)
    # a finer level labels every voxel in memory: block sums of I mu and mu^2 over the
    # chunks (chunk sides are multiples of the grid cell, so every cell is in one chunk)
    factor = grid_factor(shape)
    template = _template(shape, core)
    out_chunks = ((2,),) + tuple(tuple(-(-c // factor) for c in cs) for cs in template.chunks)
    sums = template.map_blocks(_sums_direct, window=Window(x), model=model, field=small,
                               level=f, factor=factor, chunks=out_chunks, new_axis=0,
                               dtype=np.float64, meta=np.empty((0,) * (x.ndim + 1)))
    num, den = sums.compute(**compute)
    counts = block_counts(shape, factor)
    return coarse_bias_field(num / counts, den / counts)


def _sums_direct(_, window, model, field, level, factor, block_info=None):
    """Grid-cell sums of ``I mu`` and ``mu^2`` over one chunk, mu the class means of the
    labels of `level` of the image corrected by `field` (margin 2^level, the features'
    reach, and at least the inlier window's); I the uncorrected standardised image (as
    :meth:`_bias_field` takes them)."""
    lo, hi, inner, shape = _padded(block_info, max(1 << level, LOCAL_WINDOW // 2))
    base = _work_window(window, model, None, lo, hi, shape)
    work = base if field is None else base / upsample_linear_at(
        field, shape, [np.arange(a, b) for a, b in zip(lo, hi)])
    num, den = field_terms(base, work, model._predict_level(work, level), model.class_means)
    return np.stack([block_sum(num[inner], factor, dtype=np.float64),
                     block_sum(den[inner], factor, dtype=np.float64)])
