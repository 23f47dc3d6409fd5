"""Fitting the recommended model on an image larger than memory: the boxes, read.

:meth:`~._recommended.RecommendedModel.fit` needs of the image only (see
:mod:`._training`): the pixels of the sample boxes (features are computed on each box's
own crop), the image's minimum, and, with bias correction, the bias field. So
:class:`StoreImage` reads the boxes from the store, takes the minimum in one pass over
the chunks, and estimates the field exactly as the chunked prediction does
(:func:`~._chunked.bias_round`: labels of the strided copy when the finest level is the
pixel value, else grid-cell sums of a chunked labelling pass); each box is divided by
the field's linear interpolation on its own voxels. The fit is the in-memory fit's code
(:meth:`~._recommended.RecommendedModel._fit_on`), so the model is the same to float32
rounding of the field, except for one step that needs the whole image: a store's fit
keeps the boxes' means where the in-memory fit moves them to the classified interiors'
(:mod:`._refine_em`; ``scores["refined_means"]`` says which was done).

Memory: the box crops and their features (:func:`training_bytes`, refused when over the
budget) and one padded chunk per worker in the bias passes (:func:`~._chunked.plan_chunks`).
"""

from __future__ import annotations

import numpy as np

from .._validation import check_ndim
from ._bias import grid_factor, upsample_linear_at
from ._chunked import bias_round, default_memory, plan_chunks, refuse_flat, strided_copy
from ._recommended import DEFAULT_TOP, RecommendedModel
from ._samples import Samples, check_box_contrast
from ._window_features import multiscale_feature_names

__all__ = ["fit_chunked", "training_bytes", "StoreImage"]


def training_bytes(samples: Samples, top: int, itemsize: int = 4) -> int:
    """Bytes the fit holds for the boxes: crops as stored and standardised, the feature
    stack of the largest box with its filter temporaries, the rows of one material (kept
    and concatenated) and the sampled training rows (float64, both CV halves).

    Examples
    --------
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [10, 10]}]})
    >>> training_bytes(s, 0)     # 100 px: 4+4 crops, 4*(1+0+6) stack, 8 rows, 16 sampled
    6000
    """
    f = len(multiscale_feature_names(top))
    sizes = [int(np.prod(b.shape)) for b in samples.boxes]
    per_label = [sum(n for n, b in zip(sizes, samples.boxes) if b.label == m)
                 for m in samples.labels]
    return int(sum(sizes) * (itemsize + 4) + max(sizes) * 4 * (f + top + 6)
               + max(per_label) * 8 * f + sum(per_label) * 16 * f)


class StoreImage:
    """The training image as a Dask array read box by box (see :mod:`._training`)."""

    def __init__(self, x, samples: Samples, *, minimum: float, memory: int,
                 workers: int | None, reserved: int, chunks, compute: dict):
        self.image, self.samples = x, samples
        self._minimum, self.memory, self.workers = minimum, memory, workers
        self.reserved, self.chunks, self.compute = reserved, chunks, compute
        self.small = self._raw = self._sub = None

    def minimum(self) -> float:
        return self._minimum

    def spread(self) -> float:
        return float(self.image.std(dtype=np.float64).compute(**self.compute))

    def raw_crops(self) -> list[np.ndarray]:
        if self._raw is None:
            self._raw = [np.asarray(self.image[b.slices].compute(**self.compute))
                         for b in self.samples.boxes]
        return self._raw

    def _field_at(self, box) -> np.ndarray | None:
        if self.small is None:
            return None
        return upsample_linear_at(self.small, self.image.shape,
                                  [np.arange(a, b) for a, b in zip(box.start, box.stop)])

    def crops(self, model) -> list[np.ndarray]:
        return [model._standardised(raw, self._field_at(b))
                for raw, b in zip(self.raw_crops(), self.samples.boxes)]

    def correct(self, model) -> list[float]:
        """The field of the current correction (one chunked pass), scaled as the
        estimator scales it (as prediction does), made current; the range of its grid."""
        x, f = self.image, model.finest_scale
        multiple = grid_factor(x.shape) if f > 0 else 1
        if self.chunks is None:
            core, workers = plan_chunks(x.shape, model, self.memory, workers=self.workers,
                                        reserved=self.reserved, multiple=multiple)
        else:
            core = tuple(min(n, max(multiple, c // multiple * multiple))
                         for c, n in zip(self.chunks, x.shape))
            workers = self.workers or 1
        compute = dict(self.compute)
        if compute.get("scheduler", "threads") == "threads":
            compute.setdefault("num_workers", workers)
        if f == 0 and self._sub is None:
            self._sub = np.asarray(strided_copy(x).compute(**compute))
        small = bias_round(model, x, core, self.small, sub=self._sub if f == 0 else None,
                           **compute)
        self.small = small
        return [float(small.min()), float(small.max())]

    def uncorrect(self) -> None:
        """Back to the uncorrected image (the correction did not help)."""
        self.small = None

    def release(self) -> None:
        self._raw = self._sub = self.small = None


def _first_cover(boxes, i: int) -> np.ndarray:
    """Voxels of box i that no earlier box holds (the boxes' union counts each once:
    statistics over the union of the boxes)."""
    box = boxes[i]
    keep = np.ones(box.shape, bool)
    for other in boxes[:i]:
        lo = [max(a, c) for a, c in zip(box.start, other.start)]
        hi = [min(b, d) for b, d in zip(box.stop, other.stop)]
        if all(a < b for a, b in zip(lo, hi)):
            keep[tuple(slice(a - s, b - s) for a, b, s in zip(lo, hi, box.start))] = False
    return keep


def fit_chunked(model: RecommendedModel, image, samples: Samples, *, spacing=None,
                memory: int | None = None, workers: int | None = None, reserved: int = 0,
                chunks=None, **compute) -> RecommendedModel:
    """Fit `model` on the sample boxes of a large image without loading the image.

    Parameters
    ----------
    model : RecommendedModel
        Unfitted, with its options (``max_scale``, ``bias_correction``...).
    image : (M, N[, P]) dask.array.Array or array_like
        Grey-level image (e.g. from :func:`napari_swa_imesh._zarr_io.open_lazy`).
    samples : Samples
        Materials and boxes, checked against the image here.
    spacing : sequence of float, optional
        Recorded in the model.
    memory : int, optional
        Budget in bytes for the whole process (default
        :func:`~._chunked.default_memory`).
    workers : int, optional
        Threads of the bias passes (default: planned).
    reserved : int
        Bytes of the budget already taken.
    chunks : tuple of int, optional
        Chunks of the bias passes instead of the planned ones (tests use tiny chunks).
    **compute
        Passed to ``dask.compute`` (``scheduler``...).

    Returns
    -------
    RecommendedModel
        `model`, fitted: the in-memory fit's model to float32 rounding of the field,
        with the boxes' means (``scores["refined_means"]["applied"]`` is False).

    Raises
    ------
    ValueError
        Boxes outside the image, an image of one value, NaN or infinity (one pass over
        the chunks), boxes of one value, or boxes whose features need more than the
        budget.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(4, 1, (32, 16))], 1)
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [32, 12]},
    ...                                  {"label": 2, "start": [0, 20], "stop": [32, 32]}]})
    >>> m = fit_chunked(RecommendedModel(max_scale=1), img, s, chunks=(16, 16))
    >>> ref = RecommendedModel(max_scale=1).fit(img, s)
    >>> bool((m.predict(img) == ref.predict(img)).all())
    True
    """
    import dask
    import dask.array as da

    x = image if isinstance(image, da.Array) else da.from_array(np.asarray(image))
    check_ndim(x.shape)
    if x.dtype.kind not in "biuf":
        raise TypeError(f"image must hold real numbers; got dtype {x.dtype}.")
    samples.check(x.shape)
    memory = default_memory() if memory is None else int(memory)
    top = model.max_scale if model.max_scale is not None else DEFAULT_TOP
    need = reserved + training_bytes(samples, top, x.dtype.itemsize)
    if need > memory:
        raise ValueError(
            f"training on these sample boxes needs about {need / 1e9:.2f} GB with what this "
            f"process holds, more than the budget of {memory / 1e9:.2f} GB; draw smaller "
            "boxes, give a smaller --scale or more memory (--memory).")
    lo, hi = dask.compute(x.min(), x.max(), **compute)
    refuse_flat(lo, hi)
    source = StoreImage(x, samples, minimum=float(lo), memory=memory, workers=workers,
                        reserved=reserved, chunks=chunks, compute=compute)
    check_box_contrast(source.raw_crops())
    return model._fit_on(source, samples, spacing=spacing)
