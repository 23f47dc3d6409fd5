"""The SWA pipeline: samples -> RES -> features -> classifier -> labels.

Two methods share it (``method=``, each model documents its own options):

* ``"recommended"`` (the default, :class:`RecommendedModel`): per-pixel multi-scale SWA
  statistics, coarse-to-fine at boundaries, Potts MRF, smooth-bias correction;
* ``"reference"`` (:class:`SWAModel`): the reference's tiles at one scale, feature set
  F1..F7 and GM/MD/LVQ.

A saved model brings its own method. `segment_steps` is a generator that yields
``(done, total, message)`` after each step and returns the :class:`SegmentationResult`
(napari thread workers and progress bars use it); `segment` runs it to the end.

Validate at the door, then trust: `segment_steps` checks the image and the samples once
and hands the models the checked array (``check_input=False``); the recommended method
makes one full-size float32 copy of the image, the reference one float64 copy.
"""

from __future__ import annotations

import warnings
from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage as ndi

from .._steps import run_steps
from .._timing import StepTimer
from .._validation import IMAGE_NDIM, as_image
from ._features import n_features
from ._model import SWAModel, check_scale
from ._moments import MOMENT_NAMES, tile_moments_worker
from ._recommended import RECOMMENDED_METHOD, RecommendedModel
from ._res import ResStatistics, res_statistics_unchecked
from ._samples import Samples, check_contrast
from ._signatures import material_signatures
from ._tiles import majority_tiles, tile_placement, upsample_tiles
from ._window_features import window

__all__ = ["SegmentationResult", "segment", "segment_steps", "sieve_labels",
           "upsample_tiles", "tile_placement", "material_signatures", "METHODS",
           "REFERENCE_METHOD", "REFERENCE_ONLY"]

REFERENCE_METHOD = "reference"
METHODS = (RECOMMENDED_METHOD, REFERENCE_METHOD)
REFERENCE_ONLY = ("feature_set", "classifier")     # options the recommended method has not
STEPS = 5                                         # steps segment_steps reports


@dataclass
class SegmentationResult:
    """Everything a segmentation run produced.

    Made by :func:`segment`; its fields are the constructor's parameters.

    Parameters
    ----------
    labels, tile_labels, scale, model, signatures, res, seconds, method, scales, level, notes
        The attributes below, in this order.

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
    notes : list of str
        The warnings of the run (also issued with :func:`warnings.warn`).
    """

    labels: np.ndarray
    tile_labels: np.ndarray
    scale: int
    model: SWAModel | RecommendedModel
    signatures: list[dict]
    res: ResStatistics | None = None
    seconds: dict[str, float] = field(default_factory=dict)
    method: str = REFERENCE_METHOD
    scales: tuple[int, ...] = ()
    level: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def eps_l(self) -> float | None:
        return self.model.scores.get("eps_l")

    @property
    def eps_m(self) -> float | None:
        return self.model.scores.get("eps_m")

    def pixels_per_scale(self) -> dict[int, int]:
        """Recommended method: how many pixels each scale's classifier labelled."""
        if self.level is None:
            return {}
        values, counts = np.unique(self.level, return_counts=True)
        return {int(v): int(c) for v, c in zip(values[::-1], counts[::-1])}

    def summary(self) -> dict:
        """Plain-JSON summary (what ``swa-imesh segment --json`` prints)."""
        out = {
            "method": self.method, "scales": list(self.scales or (self.scale,)),
            "scale": self.scale, "tile_size": 1 << self.scale,
            "feature_set": self.model.feature_set, "classifier": self.model.classifier_name,
            "materials": [{"label": m.label, "name": m.name} for m in self.model.materials],
            "eps_l": self.eps_l, "eps_l_method": self.model.scores.get("eps_l_method"),
            "eps_m": self.eps_m, "training_tiles": self.model.scores.get("training_tiles"),
            "eps_blocked": self.model.scores.get("eps_blocked"),
            "eps_blocked_method": self.model.scores.get("eps_blocked_method"),
            "regularized": self.model.scores.get("regularized"),
            "suggested_scale": None if self.res is None else self.res.suggested_scale,
            "suggested_reason": None if self.res is None else self.res.reason,
            "signatures": self.signatures, "seconds": self.seconds, "notes": self.notes,
        }
        if self.method == RECOMMENDED_METHOD:
            out["model"] = self.model.summary()
            if self.level is not None:
                out["pixels_per_scale"] = self.pixels_per_scale()
        return out

    def describe(self, *, notes: bool = True) -> str:
        """The run in a few lines of plain text: what the command line, the demo and the
        widget print.

        Method and scales (windows or tiles), feature set and classifier, how many pixels
        each scale labelled, the training error, regularised covariances, each material's
        signature at its scale, and (with `notes`) the run's warnings.
        """
        model = self.model
        if self.method == RECOMMENDED_METHOD:
            scales = list(self.scales)
            lines = [f"recommended method: scales {', '.join(map(str, scales))} (windows of "
                     f"{', '.join(str(window(j)) for j in scales)} px), suggested RES "
                     f"{model.res_scale}; {model.feature_set} statistics, "
                     f"{model.classifier_name.upper()}"]
            if self.level is not None:
                lines.append("pixels labelled per scale: " + ", ".join(
                    f"{j}: {n}" for j, n in self.pixels_per_scale().items()))
        else:
            lines = [f"reference method: scale {self.scale} (tiles of {1 << self.scale} px), "
                     f"{model.feature_set} + {model.classifier_name.upper()}"]
        if self.res is not None and " Capped at " in self.res.reason:
            # the boxes, not the statistics, set the scale: say which box to enlarge
            lines.append("suggested RES: c" + self.res.reason[self.res.reason.index("Capped")
                                                               + 1:])
        if self.eps_l is not None:
            lines.append(f"eps_l = {self.eps_l:.2f}% ({model.scores.get('eps_l_method')}), "
                         f"eps_m = {self.eps_m:.3f} (= -#F x eps_l / 100 with #F = "
                         f"{len(model.feature_names)} features, eq. 2.35: the error charged "
                         f"for the feature count)")
        if model.scores.get("eps_blocked") is not None:
            lines.append(f"blocked CV error = {model.scores['eps_blocked']:.2f}% "
                         f"({model.scores['eps_blocked_method']})")
        if model.scores.get("regularized"):
            lines.append(f"covariance regularised for material(s) "
                         f"{model.scores['regularized']}")
        for row in self.signatures:
            where = f" at scale {row['scale']}" if "scale" in row else ""
            if row["tiles"]:
                lines.append(f"  {row['name']}: {row['tiles']} tiles{where}, mean "
                             f"{row['mean_mean']:.4g} (+-{row['mean_std']:.3g}), variance "
                             f"{row['variance_mean']:.4g}")
            else:
                lines.append(f"  {row['name']}: no tile classified as it")
        if notes:
            lines += [f"warning: {note}" for note in self.notes]
        return "\n".join(lines)


def sieve_labels(labels: np.ndarray, min_size: int) -> np.ndarray:
    """Replace connected components smaller than `min_size` by the nearest other label.

    Components are face-connected (sec. 2.5.2.1); each pixel of a removed component takes
    the label of the nearest pixel of a kept component (Euclidean distance transform),
    so no Python loop runs per component.

    Parameters
    ----------
    labels : ndarray of int
        A label image, any dimension.
    min_size : int
        Components of fewer pixels are removed (0 or 1 keeps all).

    Returns
    -------
    ndarray of int
        The labels with small components replaced; same shape and dtype.
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


def _resolve_method(method, model, feature_set, classifier) -> str:
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose {' or '.join(METHODS)}.")
    if model is not None:
        own = model.method
        # the default ("recommended") yields to the model's own method; another does not
        if method != own and method != RECOMMENDED_METHOD:
            raise ValueError(f"the model was fitted with the {own!r} method; got "
                             f"method={method!r}. Leave the method unset to apply a model.")
        method = own
    given = [name for name, value in zip(REFERENCE_ONLY, (feature_set, classifier))
             if value is not None]
    if method == RECOMMENDED_METHOD and given:
        raise ValueError(
            f"{' and '.join(given)} belong to the reference method; drop "
            f"{'them' if len(given) > 1 else 'it'} or pass method='reference'.")
    return method


def segment_steps(image, samples: Samples | None = None, *, method: str = RECOMMENDED_METHOD,
                  scale: int | None = None, sieve: int = 0,
                  model: SWAModel | RecommendedModel | None = None, spacing=None,
                  feature_set: str | None = None, classifier: str | None = None
                  ) -> Generator[tuple[int, int, str], None, SegmentationResult]:
    """Run the segmentation step by step, yielding ``(done, total, message)``; returns the
    result. See :func:`segment` for the parameters (``total`` is 5 for both methods).

    Parameters
    ----------
    image, samples, method, scale, sieve, model, spacing, feature_set, classifier
        As for :func:`segment`.

    Yields
    ------
    done, total : int
        Steps finished, of ``total``.
    message : str
        What the step did.

    Returns
    -------
    SegmentationResult
        The generator's return value (``StopIteration.value``), as :func:`segment` returns.
    """
    if (samples is None) == (model is None):
        raise ValueError("give either sample boxes (to fit a classifier) or a fitted model, "
                         "not both and not neither.")
    chosen = _resolve_method(method, model, feature_set, classifier)
    img = as_image(image, max_ndim=IMAGE_NDIM[-1], copy=False)
    if model is None:
        samples.check(img.shape)
        check_contrast(img, samples)
    else:
        model.checked_image(img)
        if scale is not None and scale != model.scale:
            raise ValueError(f"the model works at scale {model.scale}; got scale {scale}. "
                             "Leave the scale unset when applying a saved model.")
    if chosen == RECOMMENDED_METHOD:
        return (yield from _recommended_steps(img, samples, scale=scale, sieve=sieve,
                                              model=model, spacing=spacing))
    return (yield from _reference_steps(
        img, samples, scale=scale, feature_set="F1" if feature_set is None else feature_set,
        classifier="gm" if classifier is None else classifier, sieve=sieve, model=model,
        spacing=spacing))


def _recommended_steps(img, samples, *, scale, sieve, model, spacing):
    timer = StepTimer()
    res = None
    with timer("total"):
        if model is None:
            yield 0, STEPS, "tile statistics against scale (RES)"
            with timer("res"):
                res = res_statistics_unchecked(img, samples)
            yield 1, STEPS, "fitting the multi-scale classifiers on the sample boxes"
            with timer("fit"):
                model = RecommendedModel(max_scale=scale).fit(
                    img, samples, spacing=spacing, res_scale=res.suggested_scale,
                    check_input=False)
        yield 2, STEPS, (f"classifying pixels at scales {model.scale}..{model.finest_scale} "
                         f"with MRF smoothing")
        with timer("classify"):
            labels, level = model.predict(img, check_input=False, return_level=True)
        yield 3, STEPS, "sieving and tiling"
        with timer("output"):
            if sieve:
                labels = sieve_labels(labels, int(sieve))
            tiles = majority_tiles(labels, model.scale, model.labels)
        yield 4, STEPS, "material signatures"
        with timer("signatures"):
            sig_scale = model.res_scale if model.res_scale else max(model.scale, 1)
            sig_scale = min(sig_scale, int(np.floor(np.log2(max(img.shape)))))
            moments, counts = tile_moments_worker(img, None, sig_scale)
            signatures = material_signatures(moments, counts,
                                             majority_tiles(labels, sig_scale, model.labels),
                                             model.materials)
            for row in signatures:
                row["scale"] = sig_scale
    yield 5, STEPS, "done"
    return SegmentationResult(labels, tiles, model.scale, model, signatures, res,
                              timer.seconds, method=RECOMMENDED_METHOD,
                              scales=tuple(model.scales), level=level,
                              notes=list(model.scores.get("notes", [])))


def _reference_steps(img, samples, *, scale, feature_set, classifier, sieve, model,
                     spacing):
    timer = StepTimer()
    res = None
    notes: list[str] = []
    with timer("total"):
        img = np.asarray(img, np.float64)     # the feature workers compute in float64
        if model is None:
            if scale is None:
                yield 0, STEPS, "tile statistics against scale (RES)"
                with timer("res"):
                    res = res_statistics_unchecked(img, samples, method="reference")
                scale = res.suggested_scale
                if scale is None:
                    raise ValueError(
                        "no scale leaves every material two full tiles in its boxes; draw "
                        "larger sample boxes.")
                explicit = False
            else:
                explicit = True
            check_scale(scale, img.shape)
            if classifier.lower() == "gm":
                # a class covariance needs more tiles than features; with fewer, GM fits a
                # ridge and calls every pixel the other material (measured on small boxes)
                need = n_features(feature_set.upper(), img.ndim, scale) + 1
                limit = samples.tile_limit(scale, need)
                if limit is not None:
                    if explicit or limit[0] < 0:
                        raise ValueError(limit[1] + ".")
                    notes.append(f"{limit[1]}; using scale {limit[0]}.")
                    warnings.warn(notes[-1], UserWarning, stacklevel=2)
                    scale = limit[0]
            yield 1, STEPS, (f"fitting {classifier.upper()} on {feature_set.upper()} at "
                             f"scale {scale}")
            with timer("fit"):
                model = SWAModel(scale=scale, feature_set=feature_set, classifier=classifier)
                model.fit(img, samples, spacing=spacing, check_input=False)
        yield 2, STEPS, f"classifying tiles at scale {model.scale}"
        with timer("classify"):
            feats, counts = model.tile_features(img, check_input=False)
            tiles = model.classify_features(feats)
        yield 3, STEPS, "sieving and upsampling"
        with timer("output"):
            if sieve:
                tiles = sieve_labels(tiles, int(sieve))
            labels = upsample_tiles(tiles, model.scale, img.shape)
        yield 4, STEPS, "material signatures"
        with timer("signatures"):
            if set(MOMENT_NAMES) <= set(model.feature_names):   # the moments are features
                moments = feats[..., [model.feature_names.index(n) for n in MOMENT_NAMES]]
            else:
                moments, counts = tile_moments_worker(img, None, model.scale)
            del feats
            signatures = material_signatures(moments, counts, tiles, model.materials)
            for row in signatures:          # the tile side a stochastic run correlates over
                row["scale"] = model.scale
    yield 5, STEPS, "done"
    return SegmentationResult(labels, tiles, model.scale, model, signatures, res,
                              timer.seconds, method=REFERENCE_METHOD, scales=(model.scale,),
                              notes=notes)


def segment(image, samples: Samples | None = None, *, method: str = RECOMMENDED_METHOD,
            scale: int | None = None, sieve: int = 0,
            model: SWAModel | RecommendedModel | None = None, spacing=None,
            feature_set: str | None = None, classifier: str | None = None
            ) -> SegmentationResult:
    """Segment an image with SWA.

    Parameters
    ----------
    image : (M, N[, P, ...]) array_like
        Grey-level image, any size (non-dyadic sizes are handled without padding leaking
        into statistics). Checked here, once; never modified.
    samples : Samples, optional
        Sample boxes per material (to fit a classifier). Give this or `model`.
    method : {"recommended", "reference"}
        "recommended" (:class:`RecommendedModel`) or the reference's tiles at one scale
        (:class:`SWAModel`). With `model`, the model's own method is used (another
        explicit method is an error).
    scale : int, optional
        Means what the method's model says. Recommended: the *largest* scale considered
        (windows of 2^scale + 1 px; default the suggested RES, capped at 6); the model
        picks its scales below it. Reference: *the* tile scale j (tiles of 2^j px; default
        the suggested RES).
    sieve : int
        Remove connected components smaller than this: *pixels* with the recommended
        method (full-resolution labels), *tiles* with the reference (tile labels); 0: off.
    model : SWAModel or RecommendedModel, optional
        A fitted model to apply instead of fitting one (it brings its method).
    spacing : sequence of float, optional
        Voxel spacing, recorded in the model.
    feature_set : {"F1", ..., "F7"}, optional
        Reference only: Table 2.1 feature set (default F1, moments).
    classifier : {"gm", "md", "lvq"}, optional
        Reference only: the classifier (default GM, Gaussian maximum likelihood).

    Returns
    -------
    SegmentationResult

    Raises
    ------
    ValueError
        For a bad image or samples, and for `feature_set` or `classifier` with the
        recommended method (they belong to the reference method).

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
    gen = segment_steps(image, samples, method=method, scale=scale, sieve=sieve,
                        model=model, spacing=spacing, feature_set=feature_set,
                        classifier=classifier)
    return run_steps(gen)
