"""The SWA pipeline: samples -> RES -> features at the scale -> classifier -> labels.

`segment_steps` is a generator that yields ``(done, total, message)`` after each step and
returns the :class:`SegmentationResult` (napari thread workers and progress bars use it);
`segment` runs it to the end.
"""

from __future__ import annotations

import time
from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage as ndi

from .._validation import as_image, normalize_spacing
from ._model import SWAModel
from ._moments import tile_moments
from ._res import MOMENT_NAMES, ResStatistics, res_statistics
from ._samples import Samples

__all__ = ["SegmentationResult", "segment", "segment_steps", "sieve_labels",
           "upsample_tiles", "tile_placement", "material_signatures"]


@dataclass
class SegmentationResult:
    """Everything a segmentation run produced.

    Attributes
    ----------
    labels : ndarray of int32
        Full-resolution labels, exactly the input image's shape.
    tile_labels : ndarray of int32
        One label per tile (shape ``ceil(shape / 2**scale)``); place it over the image with
        :func:`tile_placement`.
    scale : int
        Tile scale used.
    model : SWAModel
        The fitted (or loaded) classifier.
    signatures : list of dict
        Per material: tiles, and mean and std of each moment over its tiles at the scale.
    res : ResStatistics or None
        RES statistics when they were computed (no ``scale`` given and samples given).
    seconds : dict of str to float
        Wall-clock time per step.
    """

    labels: np.ndarray
    tile_labels: np.ndarray
    scale: int
    model: SWAModel
    signatures: list[dict]
    res: ResStatistics | None = None
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def eps_l(self) -> float | None:
        return self.model.scores.get("eps_l")

    @property
    def eps_m(self) -> float | None:
        return self.model.scores.get("eps_m")

    def summary(self) -> dict:
        """Plain-JSON summary (what ``swa-imesh segment --json`` prints)."""
        return {
            "scale": self.scale, "tile_size": 1 << self.scale,
            "feature_set": self.model.feature_set, "classifier": self.model.classifier_name,
            "materials": [{"label": m.label, "name": m.name} for m in self.model.materials],
            "eps_l": self.eps_l, "eps_l_method": self.model.scores.get("eps_l_method"),
            "eps_m": self.eps_m, "training_tiles": self.model.scores.get("training_tiles"),
            "regularized": self.model.scores.get("regularized"),
            "suggested_scale": None if self.res is None else self.res.suggested_scale,
            "signatures": self.signatures, "seconds": self.seconds,
        }


def upsample_tiles(tile_labels: np.ndarray, scale: int, shape: tuple[int, ...]) -> np.ndarray:
    """Full-resolution labels from tile labels: repeat each tile 2^scale times, crop to `shape`.

    Examples
    --------
    >>> upsample_tiles(np.array([[1, 2]]), 1, (2, 3)).tolist()
    [[1, 1, 2], [1, 1, 2]]
    """
    out = tile_labels
    s = 1 << scale
    for axis in range(tile_labels.ndim):
        out = np.repeat(out, s, axis=axis)
    return np.ascontiguousarray(out[tuple(slice(0, n) for n in shape)])


def tile_placement(scale: int, spacing=None, ndim: int | None = None
                   ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Layer ``scale`` and ``translate`` that put tile labels exactly over the image.

    napari puts pixel i's centre at ``i * spacing``; a tile of s = 2^scale pixels covers
    pixels t*s .. t*s+s-1, so its centre sits at ``t*s*spacing + (s-1)/2*spacing``.
    """
    sp = normalize_spacing(spacing, ndim if ndim is not None else len(spacing))
    s = 1 << scale
    return tuple(v * s for v in sp), tuple(v * (s - 1) / 2 for v in sp)


def sieve_labels(labels: np.ndarray, min_size: int) -> np.ndarray:
    """Replace connected components smaller than `min_size` by the nearest other label.

    Components are face-connected (sec. 2.5.2.1); each pixel of a removed component takes
    the label of the nearest pixel of a kept component (Euclidean distance transform),
    so no Python loop runs per component.
    """
    if min_size <= 1:
        return labels.copy()
    keep = np.zeros(labels.shape, bool)
    for value in np.unique(labels):
        comp, n = ndi.label(labels == value)
        if n == 0:
            continue
        sizes = np.bincount(comp.ravel())
        big = sizes >= min_size
        big[0] = False
        keep |= big[comp]
    if keep.all() or not keep.any():
        return labels.copy()
    _, idx = ndi.distance_transform_edt(~keep, return_indices=True)
    return labels[tuple(idx)]


def material_signatures(moments: np.ndarray, counts: np.ndarray, tile_labels: np.ndarray,
                        model: SWAModel, names: dict[int, str] | None = None) -> list[dict]:
    """Per material: mean and std of each moment over the full tiles classified as it."""
    full = counts == counts.max()
    rows = []
    for m in model.materials:
        sel = full & (tile_labels == m.label)
        tiles = moments[sel]
        row = {"label": m.label, "name": m.name, "tiles": int(sel.sum())}
        for k, name in enumerate(MOMENT_NAMES):
            row[f"{name}_mean"] = float(tiles[:, k].mean()) if tiles.size else float("nan")
            row[f"{name}_std"] = float(tiles[:, k].std()) if tiles.size else float("nan")
        rows.append(row)
    return rows


def segment_steps(image, samples: Samples | None = None, *, scale: int | None = None,
                  feature_set: str = "F1", classifier: str = "gm", sieve: int = 0,
                  model: SWAModel | None = None, spacing=None
                  ) -> Generator[tuple[int, int, str], None, SegmentationResult]:
    """Run SWA step by step, yielding ``(done, total, message)``; returns the result.

    See :func:`segment` for the parameters.
    """
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    img = as_image(image)
    if (samples is None) == (model is None):
        raise ValueError("give either sample boxes (to fit a classifier) or a fitted model, "
                         "not both and not neither.")
    total = 5
    res = None
    if model is None:
        samples.check(img.shape)
        if scale is None:
            yield 0, total, "tile statistics against scale (RES)"
            res = res_statistics(img, samples)
            scale = res.suggested_scale
            if scale is None:
                raise ValueError(
                    "no scale leaves every material two full tiles in its boxes; draw larger "
                    "sample boxes.")
            seconds["res"] = time.perf_counter() - t0
        yield 1, total, f"fitting {classifier.upper()} on {feature_set.upper()} at scale {scale}"
        t = time.perf_counter()
        model = SWAModel(scale=scale, feature_set=feature_set, classifier=classifier)
        model.fit(img, samples, spacing=spacing)
        seconds["fit"] = time.perf_counter() - t
    elif scale is not None and scale != model.scale:
        raise ValueError(f"the model works at scale {model.scale}; got scale={scale}. "
                         "Leave the scale unset when applying a saved model.")
    yield 2, total, f"classifying tiles at scale {model.scale}"
    t = time.perf_counter()
    tiles = model.predict_tiles(img)
    seconds["classify"] = time.perf_counter() - t
    yield 3, total, "sieving and upsampling"
    t = time.perf_counter()
    if sieve:
        tiles = sieve_labels(tiles, int(sieve))
    labels = upsample_tiles(tiles, model.scale, img.shape)
    seconds["output"] = time.perf_counter() - t
    yield 4, total, "material signatures"
    t = time.perf_counter()
    moments, counts = tile_moments(img, model.scale)
    signatures = material_signatures(moments, counts, tiles, model)
    seconds["signatures"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    yield 5, total, "done"
    return SegmentationResult(labels, tiles, model.scale, model, signatures, res, seconds)


def segment(image, samples: Samples | None = None, *, scale: int | None = None,
            feature_set: str = "F1", classifier: str = "gm", sieve: int = 0,
            model: SWAModel | None = None, spacing=None) -> SegmentationResult:
    """Segment an image with SWA (the reference method).

    Parameters
    ----------
    image : (M, N[, P, ...]) array_like
        Grey-level image, any size (non-dyadic sizes are handled without padding leaking
        into statistics).
    samples : Samples, optional
        Sample boxes per material (to fit a classifier). Give this or `model`.
    scale : int, optional
        Tile scale j; default the suggested RES of the samples.
    feature_set : {"F1", ..., "F7"}
        Table 2.1 feature set; F1 (moments) by default.
    classifier : {"gm", "md", "lvq"}
        Gaussian maximum likelihood by default.
    sieve : int
        Remove connected components smaller than this many tiles (0: off).
    model : SWAModel, optional
        A fitted model to apply instead of fitting one.
    spacing : sequence of float, optional
        Voxel spacing, recorded in the model.

    Returns
    -------
    SegmentationResult
    """
    gen = segment_steps(image, samples, scale=scale, feature_set=feature_set,
                        classifier=classifier, sieve=sieve, model=model, spacing=spacing)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value
