"""The SWA pipeline: samples -> RES -> features -> classifier -> labels.

Two methods share it (``method=``):

* ``"recommended"`` (the default): per-pixel multi-scale SWA statistics, coarse-to-fine at
  boundaries, Potts MRF, smooth-bias correction (:mod:`._recommended`);
* ``"reference"``: the reference's tiles at one scale, feature set F1..F7 and GM/MD/LVQ
  (:class:`SWAModel`), unchanged.

Rule: giving any of ``scale``, ``feature_set`` or ``classifier`` without ``method`` selects
the reference (those are its knobs, so old calls keep their results); a saved model brings
its own method.

`segment_steps` is a generator that yields ``(done, total, message)`` after each step and
returns the :class:`SegmentationResult` (napari thread workers and progress bars use it);
`segment` runs it to the end.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage as ndi

from .._validation import as_image, normalize_spacing
from ._features import n_features
from ._model import SWAModel, _check_scale
from ._moments import tile_moments
from ._recommended import RECOMMENDED_METHOD, RecommendedModel, majority_tiles, \
    potts_mean_field
from ._res import MOMENT_NAMES, ResStatistics, res_statistics
from ._samples import Samples

__all__ = ["SegmentationResult", "segment", "segment_steps", "sieve_labels",
           "upsample_tiles", "tile_placement", "material_signatures", "METHODS"]

METHODS = (RECOMMENDED_METHOD, "reference")


@dataclass
class SegmentationResult:
    """Everything a segmentation run produced.

    Attributes
    ----------
    labels : ndarray of int32 (int64 for labels >= 2^31)
        Full-resolution labels, exactly the input image's shape.
    tile_labels : ndarray of int32 (int64 for labels >= 2^31)
        One label per tile (shape ``ceil(shape / 2**scale)``); place it over the image with
        :func:`tile_placement`. With the recommended method: the majority label per tile.
    scale : int
        Tile scale used (reference), or the coarsest scale whose statistics the
        recommended classifier uses (windows of 2^scale + 1 px).
    model : SWAModel or RecommendedModel
        The fitted (or loaded) classifier.
    signatures : list of dict
        Per material: tiles, and mean and std of each moment over its tiles at the scale
        (recommended: at the suggested RES, with majority tile labels).
    res : ResStatistics or None
        RES statistics when they were computed.
    seconds : dict of str to float
        Wall-clock time per step.
    method : {"reference", "recommended"}
    scales : tuple of int
        Every scale whose classifier labelled some pixel (coarse first); ``(scale,)`` for
        the reference.
    level : ndarray of int8 or None
        Recommended method: the scale that labelled each pixel (finer at boundaries).
    """

    labels: np.ndarray
    tile_labels: np.ndarray
    scale: int
    model: SWAModel | RecommendedModel
    signatures: list[dict]
    res: ResStatistics | None = None
    seconds: dict[str, float] = field(default_factory=dict)
    method: str = "reference"
    scales: tuple[int, ...] = ()
    level: np.ndarray | None = None

    @property
    def eps_l(self) -> float | None:
        return self.model.scores.get("eps_l")

    @property
    def eps_m(self) -> float | None:
        return self.model.scores.get("eps_m")

    def summary(self) -> dict:
        """Plain-JSON summary (what ``swa-imesh segment --json`` prints)."""
        out = {
            "method": self.method, "scales": list(self.scales or (self.scale,)),
            "scale": self.scale, "tile_size": 1 << self.scale,
            "feature_set": self.model.feature_set, "classifier": self.model.classifier_name,
            "materials": [{"label": m.label, "name": m.name} for m in self.model.materials],
            "eps_l": self.eps_l, "eps_l_method": self.model.scores.get("eps_l_method"),
            "eps_m": self.eps_m, "training_tiles": self.model.scores.get("training_tiles"),
            "regularized": self.model.scores.get("regularized"),
            "suggested_scale": None if self.res is None else self.res.suggested_scale,
            "signatures": self.signatures, "seconds": self.seconds,
        }
        if self.method == RECOMMENDED_METHOD:
            out["model"] = self.model.summary()
            if self.level is not None:
                values, counts = np.unique(self.level, return_counts=True)
                out["pixels_per_scale"] = {int(v): int(c) for v, c in zip(values, counts)}
        return out


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


def _resolve_method(method, model, scale, feature_set, classifier) -> str:
    if model is not None:
        own = getattr(model, "method", "reference")
        if method is not None and method != own:
            raise ValueError(f"the model was fitted with the {own!r} method; got "
                             f"method={method!r}. Leave the method unset to apply a model.")
        return own
    if method is None:
        explicit = scale is not None or feature_set is not None or classifier is not None
        return "reference" if explicit else RECOMMENDED_METHOD
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose {' or '.join(METHODS)}.")
    if method == RECOMMENDED_METHOD and (feature_set is not None or classifier is not None):
        raise ValueError(
            "feature_set and classifier belong to the reference method; drop them or pass "
            "method='reference'.")
    return method


def segment_steps(image, samples: Samples | None = None, *, scale: int | None = None,
                  feature_set: str | None = None, classifier: str | None = None,
                  sieve: int = 0, model: SWAModel | RecommendedModel | None = None,
                  spacing=None, method: str | None = None
                  ) -> Generator[tuple[int, int, str], None, SegmentationResult]:
    """Run the segmentation step by step, yielding ``(done, total, message)``; returns the
    result. See :func:`segment` for the parameters (``total`` is 5 for both methods).
    """
    if (samples is None) == (model is None):
        raise ValueError("give either sample boxes (to fit a classifier) or a fitted model, "
                         "not both and not neither.")
    chosen = _resolve_method(method, model, scale, feature_set, classifier)
    if chosen == RECOMMENDED_METHOD:
        return (yield from _recommended_steps(image, samples, scale=scale, sieve=sieve,
                                              model=model, spacing=spacing))
    return (yield from _reference_steps(
        image, samples, scale=scale, feature_set="F1" if feature_set is None else feature_set,
        classifier="gm" if classifier is None else classifier, sieve=sieve, model=model,
        spacing=spacing))


def _recommended_steps(image, samples, *, scale, sieve, model, spacing):
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    img = as_image(image)
    total = 5
    res = None
    if model is None:
        samples.check(img.shape)
        yield 0, total, "tile statistics against scale (RES)"
        res = res_statistics(img, samples)
        seconds["res"] = time.perf_counter() - t0
        yield 1, total, "fitting the multi-scale classifiers on the sample boxes"
        t = time.perf_counter()
        model = RecommendedModel(max_scale=scale)
        model.fit(img, samples, spacing=spacing, res_scale=res.suggested_scale)
        seconds["fit"] = time.perf_counter() - t
    elif scale is not None and scale != model.scale:
        raise ValueError(f"the model works at scale {model.scale}; got scale {scale}. "
                         "Leave the scale unset when applying a saved model.")
    yield 2, total, (f"classifying pixels at scales {model.scale}..{model.finest_scale} "
                     f"with MRF smoothing")
    t = time.perf_counter()
    img = model._check_image(img)
    ll, level = model._labels_and_ll(img)
    labels = model.label_values()[potts_mean_field(ll, model.beta, labels_only=True)]
    del ll
    seconds["classify"] = time.perf_counter() - t
    yield 3, total, "sieving and tiling"
    t = time.perf_counter()
    if sieve:
        labels = sieve_labels(labels, int(sieve))
    tiles = majority_tiles(labels, model.scale, model.labels)
    seconds["output"] = time.perf_counter() - t
    yield 4, total, "material signatures"
    t = time.perf_counter()
    sig_scale = model.res_scale if model.res_scale else max(model.scale, 1)
    sig_scale = min(sig_scale, int(np.floor(np.log2(max(img.shape)))))
    moments, counts = tile_moments(img, sig_scale)
    signatures = material_signatures(moments, counts,
                                     majority_tiles(labels, sig_scale, model.labels), model)
    for row in signatures:
        row["scale"] = sig_scale
    seconds["signatures"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    yield 5, total, "done"
    return SegmentationResult(labels, tiles, model.scale, model, signatures, res, seconds,
                              method=RECOMMENDED_METHOD, scales=tuple(model.scales),
                              level=level)


def _reference_steps(image, samples, *, scale, feature_set, classifier, sieve, model,
                     spacing):
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    img = as_image(image)
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
            explicit = False
        else:
            explicit = True
        _check_scale(scale, img.shape)
        if classifier.lower() == "gm":
            # a class covariance needs more tiles than features; with fewer, GM fits a
            # ridge and calls every pixel the other material (measured on small boxes)
            need = n_features(feature_set.upper(), img.ndim, scale) + 1
            limit = samples.tile_limit(scale, need)
            if limit is not None:
                if explicit or limit[0] < 0:
                    raise ValueError(limit[1] + ".")
                warnings.warn(f"{limit[1]}; using scale {limit[0]}.", UserWarning,
                              stacklevel=2)
                scale = limit[0]
        yield 1, total, f"fitting {classifier.upper()} on {feature_set.upper()} at scale {scale}"
        t = time.perf_counter()
        model = SWAModel(scale=scale, feature_set=feature_set, classifier=classifier)
        model.fit(img, samples, spacing=spacing)
        seconds["fit"] = time.perf_counter() - t
    elif scale is not None and scale != model.scale:
        raise ValueError(f"the model works at scale {model.scale}; got scale {scale}. "
                         "Leave the scale unset when applying a saved model.")
    yield 2, total, f"classifying tiles at scale {model.scale}"
    t = time.perf_counter()
    feats, counts = model.tile_features(img)
    tiles = model.classify_features(feats)
    seconds["classify"] = time.perf_counter() - t
    yield 3, total, "sieving and upsampling"
    t = time.perf_counter()
    if sieve:
        tiles = sieve_labels(tiles, int(sieve))
    labels = upsample_tiles(tiles, model.scale, img.shape)
    seconds["output"] = time.perf_counter() - t
    yield 4, total, "material signatures"
    t = time.perf_counter()
    if set(MOMENT_NAMES) <= set(model.feature_names):   # the moments are features already
        moments = feats[..., [model.feature_names.index(n) for n in MOMENT_NAMES]]
    else:
        moments, counts = tile_moments(img, model.scale)
    del feats
    signatures = material_signatures(moments, counts, tiles, model)
    seconds["signatures"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    yield 5, total, "done"
    return SegmentationResult(labels, tiles, model.scale, model, signatures, res, seconds,
                              method="reference", scales=(model.scale,))


def segment(image, samples: Samples | None = None, *, scale: int | None = None,
            feature_set: str | None = None, classifier: str | None = None, sieve: int = 0,
            model: SWAModel | RecommendedModel | None = None, spacing=None,
            method: str | None = None) -> SegmentationResult:
    """Segment an image with SWA.

    Parameters
    ----------
    image : (M, N[, P, ...]) array_like
        Grey-level image, any size (non-dyadic sizes are handled without padding leaking
        into statistics).
    samples : Samples, optional
        Sample boxes per material (to fit a classifier). Give this or `model`.
    scale : int, optional
        Reference: the tile scale j (default the suggested RES). Recommended: the largest
        scale considered (default the suggested RES, capped at 6).
    feature_set : {"F1", ..., "F7"}, optional
        Reference only: Table 2.1 feature set (default F1, moments).
    classifier : {"gm", "md", "lvq"}, optional
        Reference only: the classifier (default GM, Gaussian maximum likelihood).
    sieve : int
        Remove connected components smaller than this many tiles (reference) or pixels
        (recommended); 0: off.
    model : SWAModel or RecommendedModel, optional
        A fitted model to apply instead of fitting one (it brings its method).
    spacing : sequence of float, optional
        Voxel spacing, recorded in the model.
    method : {"recommended", "reference"}, optional
        Default: "reference" when `scale`, `feature_set` or `classifier` is given (the
        reference's own knobs, so such calls keep their results), else "recommended".

    Returns
    -------
    SegmentationResult

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(4, 1, (32, 16))], 1)
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [32, 12]},
    ...                                  {"label": 2, "start": [0, 20], "stop": [32, 32]}]})
    >>> r = segment(img, s)
    >>> r.method, r.labels.shape, int((r.labels[:, :16] == 1).mean() > 0.95)
    ('recommended', (32, 32), 1)
    """
    gen = segment_steps(image, samples, scale=scale, feature_set=feature_set,
                        classifier=classifier, sieve=sieve, model=model, spacing=spacing,
                        method=method)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value
