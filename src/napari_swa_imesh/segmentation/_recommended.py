"""The recommended segmentation method: multi-scale SWA statistics per pixel, refined
coarse-to-fine at boundaries, regularised by a Potts MRF, with a smooth-bias correction.

Why each part is here (measured on the texture mosaics and 3-D tissue phantoms of
``benchmarks/bench_accuracy.py``; the reference's F1 + GM at one tile scale is kept in
:class:`~napari_swa_imesh.segmentation.SWAModel`):

* **Per-pixel statistics in sliding windows** (:mod:`._window_features`): labels are full
  resolution and never shifted.
* **Which scales: chosen from the samples, visible to the user.** Every level
  0..Jmax (Jmax: the suggested RES of the sample boxes) gets a Gaussian maximum-likelihood
  classifier (GM, eq. 2.30) on standardised features, scored by 2-fold cross-validation on
  pixels of the boxes. The coarse level J is the smallest whose error is within
  ``tolerance`` of the best; it labels the image first.
* **Boundaries: coarse-to-fine, as the reference's future-work tree refinement.** A pixel
  whose level-j window straddles two labels has mixed statistics; it is relabelled by
  level j-1, down to the finest level whose cross-validated error is at most
  ``refine_error`` percent (12: textures stop one or two levels below J, where the MRF can
  still repair the finer level's mistakes; intensity-distinct tissues refine to the pixel).
* **Spatial regularisation**: a Potts MRF (:mod:`._mrf`, beta 2).
* **Smooth multiplicative bias** (:mod:`._bias`): the image is divided by the field and
  the classifiers refitted, :data:`BIAS_ROUNDS` times; kept only where it helps
  (``"auto"``). The field is a low-order polynomial of its log, of the degree held-out
  cells support (flat unless there is evidence), fitted on inlier pixels only, so
  background that no material describes does not pull it.
* **Errors a user can believe**: besides the pixel CV, a blocked CV over half-boxes
  (:mod:`._blocked_cv`) per level.

Explainability: :meth:`RecommendedModel.summary` lists the cross-validated error of every
level, the scales used (windows in px), and the features with the largest Fisher ratios;
:func:`~._res.plot_res_scales` shades the scales used on the RES plot.
"""

from __future__ import annotations

import warnings
from functools import partial

import numpy as np
from scipy import ndimage as ndi

from ._bias import estimate_bias_field, inlier_class_means, upsample_linear
from ._blocked_cv import BLOCKED_CV_METHOD, blocked_cv_errors
from ._classifiers import GaussianClassifier
from ._model_base import SegmentationModel
from ._mrf import argmax_first, potts_mean_field
from ._refine_em import refine_fitted
from ._res import res_statistics_unchecked
from ._samples import BoxCrops, Material, Samples
from ._tiles import majority_tiles
from ._training import WholeImage
from ._window_features import feature_levels, multiscale_features, window

__all__ = ["RecommendedModel", "RECOMMENDED_METHOD", "BIAS_ROUNDS", "FIELD_GRID"]

RECOMMENDED_METHOD = "recommended"
BIAS_ROUNDS = 2         # field estimates per fit or prediction: the second one labels the
#                         once-corrected image, so a strong bias cannot mislabel it twice
MAX_SCALE = 8           # windows up to 257 px per axis
DEFAULT_TOP = 6         # the RES suggestion is capped here (65-px windows) ...
NO_RES_TOP = 2          # ... and without a suggestion (too few tiles) levels go to 2
AUTO_GAIN = 0.0         # "auto" bias correction: kept if the field is not flat (the
#                         estimator's own held-out test) and it shrinks the within-material
#                         variance at all (a 1 % threshold, tuned on one generator, turned
#                         a 40 % field off on another)
FIELD_GRID = 64         # pixel-value level: label ~64 px along the shortest side for the field
_SLAB = 1 << 20         # pixels per slab when standardising (bounds float64 temporaries)
_TOP_FEATURES = 8       # features listed by summary()


class RecommendedModel(SegmentationModel):
    """Multi-scale per-pixel SWA classifier with boundary refinement, MRF and bias correction.

    See the module docstring for the method. Fitted attributes follow :class:`SWAModel`
    where they mean the same thing, so code written for it (and the model file) keeps
    working: ``scale`` is the coarse level J, ``materials``, ``feature_names`` (of level
    J), ``ndim``, ``spacing``, ``scores``.

    Options of the reference method do not apply: there is no feature set (the window
    statistics are fixed) and no classifier choice (GM per level). ``segment(scale=j)``
    is this model's `max_scale`, and ``segment(sieve=n)`` removes components smaller than
    n *pixels* (the reference counts tiles).

    Parameters
    ----------
    max_scale : int, optional
        Largest scale considered (windows of 2^j + 1 px), 0..8; default the suggested RES
        of the samples, capped at 6. Levels that no box of some material can hold are
        dropped with a warning.
    tolerance : float
        Coarse level: the smallest whose cross-validated error (percent) is within this
        of the best level's.
    refine_error : float
        Boundary refinement goes down to the finest level with at most this error (percent).
    beta : float
        Potts coupling of the MRF (0: off).
    bias_correction : bool or "auto"
        Estimate and remove a smooth multiplicative intensity bias. The field is exactly
        1 unless a smooth field predicts held-out parts of the image better
        (:func:`~._bias.coarse_bias_field`); "auto" then keeps the correction only when it
        is not flat and shrinks the within-material variance of the pixel values in the
        sample boxes (on texture mosaics it does not: there it would only add time).
    pixels_per_material : int
        Training pixels sampled per material (all, if the boxes hold fewer).
    seed : int
        Seed of the pixel sampling and CV split.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(0, 3, (32, 16))], 1)
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [32, 16]},
    ...                                  {"label": 2, "start": [0, 16], "stop": [32, 32]}]})
    >>> m = RecommendedModel(max_scale=2).fit(img, s)
    >>> m.predict(img).shape
    (32, 32)
    """

    method = RECOMMENDED_METHOD
    feature_set = "multiscale"
    classifier_name = "gm+mrf"

    def __init__(self, *, max_scale: int | None = None, tolerance: float = 1.0,
                 refine_error: float = 12.0, beta: float = 2.0,
                 bias_correction: bool | str = "auto",
                 pixels_per_material: int = 20000, seed: int = 0):
        if max_scale is not None and not 0 <= int(max_scale) <= MAX_SCALE:
            raise ValueError(f"max_scale must be 0..{MAX_SCALE} (windows up to "
                             f"{window(MAX_SCALE)} px); got {max_scale}.")
        if beta < 0:
            raise ValueError(f"beta must be >= 0; got {beta}.")
        self.max_scale = None if max_scale is None else int(max_scale)
        self.tolerance = float(tolerance)
        self.refine_error = float(refine_error)
        self.beta = float(beta)
        if bias_correction not in (True, False, "auto"):
            raise ValueError(f"bias_correction must be True, False or 'auto'; got "
                             f"{bias_correction!r}.")
        self.bias_correction = bias_correction
        self.pixels_per_material = int(pixels_per_material)
        self.seed = int(seed)
        self.coherence = True       # False only for model files saved before these features
        self.scale = 0              # coarse level J
        self.finest_scale = 0       # refinement stops here
        self.res_scale: int | None = None
        self.levels: dict[int, GaussianClassifier] = {}
        self.level_error: dict[int, float] = {}
        self.class_means: dict[int, float] = {}
        self.materials: list[Material] = []
        self.feature_names: list[str] = []
        self.fisher: dict[str, float] = {}
        self.ndim: int | None = None
        self.spacing: tuple[float, ...] | None = None
        self.intensity: tuple[float, float] = (0.0, 1.0)   # (offset, scale), see fit
        self.scores: dict = {}

    def _class_values(self) -> np.ndarray:
        """Labels in class-index order (sorted, as every level's ``classes_``)."""
        return np.sort(self.label_values())

    @property
    def scales(self) -> list[int]:
        """Levels the labels can come from: coarse level J down to the finest refinement."""
        return list(range(self.scale, self.finest_scale - 1, -1))

    # -- fitting ---------------------------------------------------------------------------
    def fit(self, image, samples: Samples, *, spacing=None, res_scale: int | None = None,
            check_input: bool = True) -> RecommendedModel:
        """Fit a classifier per level on pixels of the sample boxes, choose the levels.

        Parameters
        ----------
        image : (M, N[, P]) array_like
        samples : Samples
        spacing : sequence of float, optional
            Recorded in the model.
        res_scale : int, optional
            The suggested RES of the samples (used as the largest scale when `max_scale`
            is not set); computed here when not given.
        check_input : bool
            False: `samples` were checked against the float `image` (see
            :mod:`._model_base`).
        """
        img = self.checked_training_image(image, samples, check_input)
        return self._fit_on(WholeImage(img, samples), samples, spacing=spacing,
                            res_scale=res_scale)

    def _fit_on(self, source, samples: Samples, *, spacing=None,
                res_scale: int | None = None) -> RecommendedModel:
        """:meth:`fit` on a checked training image seen through `source`: the whole
        image in memory (:class:`~._training.WholeImage`) or a store read box by box
        (:mod:`._chunked_fit`); everything else is the same code."""
        if res_scale is None and self.max_scale is None:
            res_scale = res_statistics_unchecked(source.image, samples).suggested_scale
        self.res_scale = res_scale
        top = self.max_scale if self.max_scale is not None else min(
            DEFAULT_TOP, res_scale if res_scale is not None else NO_RES_TOP)
        limit = samples.window_limit(top)
        notes = []
        if limit is not None:
            # box sizes are the user's, not the image's: a level no box of some material
            # can train is never used (the scale is a maximum), and the user hears which
            # box to enlarge
            notes.append(f"{limit[1]}; using scales up to {limit[0]}.")
            warnings.warn(notes[-1], UserWarning, stacklevel=3)
            top = limit[0]
        self.materials = list(samples.materials)
        self.ndim = source.image.ndim
        self.spacing = None if spacing is None else tuple(float(s) for s in spacing)
        # intensities in units of the boxes' spread above the image minimum: every result
        # is invariant to x -> a x + b (a > 0), and the bias stays multiplicative
        inside = np.concatenate([np.asarray(c, np.float64).ravel()
                                 for c in source.raw_crops()])
        self.intensity = (source.minimum(), float(inside.std()) or source.spread())
        del inside
        bias_range = None
        rounds = BIAS_ROUNDS + 1 if self.bias_correction else 1
        first = None
        for r in range(rounds):
            # the first round picks the levels; the bias rounds refit only the level that
            # labels the image for the field, the last round refits every level
            X, y, names = self._training_rows(source.crops(self), samples,
                                              top if r in (0, rounds - 1)
                                              else self.finest_scale)
            if r in (0, rounds - 1):
                self._fit_levels(X, y, names)
                if r == 0:
                    first = (X, y, names, dict(self.class_means))
            else:
                self.levels[self.finest_scale] = GaussianClassifier(priors="equal").fit(X, y)
            if r + 1 < rounds:
                self.class_means = inlier_class_means(
                    source.crops(self), partial(self._predict_level, level=self.finest_scale),
                    self.class_means)
                bias_range = source.correct(self)
        reduction = None
        if rounds > 1:
            reduction = 1.0 - _within_variance(X[:, 0], y) / max(
                _within_variance(first[0][:, 0], first[1]), 1e-300)
            if self.bias_correction == "auto" and reduction <= AUTO_GAIN:
                X, y, names, self.class_means = first
                self._fit_levels(X, y, names)
                bias_range = None
                source.uncorrect()
        refined = refine_fitted(self, source)       # box means -> interiors' (J = 0)
        # the number a user should believe: folds of whole half-boxes, not of pixels (levels
        # up to J only: the labels come from no coarser one, and 65-px windows on big boxes
        # cost seconds on 256^3); the halves are read from the final crops, so a store
        # source needs no whole image
        blocked = blocked_cv_errors(BoxCrops(source.crops(self), samples.boxes), samples,
                                    self.scale, per_material=self.pixels_per_material,
                                    seed=self.seed, coherence=self.coherence)
        source.release()
        if self.bias_correction == "auto":
            self.bias_correction = bias_range is not None
        self._fisher(X, y, names)
        err = self.level_error[self.scale]
        self.scores = {
            "eps_l": err, "eps_l_method": "2-fold cross-validation over sampled pixels of the "
                                          "boxes (pixels are correlated: optimistic)",
            "eps_m": -len(self.feature_names) * err / 100.0,
            "eps_blocked": None if blocked is None else blocked[self.scale],
            "eps_blocked_method": BLOCKED_CV_METHOD if blocked is not None else
            "not computed: some material has only 1-px-thick boxes",
            "level_error_blocked": None if blocked is None else {
                str(j): e for j, e in blocked.items()},
            "training_pixels": {int(m): int(np.sum(y == m)) for m in samples.labels},
            "level_error": {str(j): e for j, e in self.level_error.items()},
            "regularized": sorted({int(c) for clf in self.levels.values()
                                   for c, reg in zip(clf.classes_, clf.regularized_) if reg}),
            "bias_correction": bool(self.bias_correction),
            "bias_variance_reduction": reduction,
            "bias_range": bias_range, "refined_means": refined,
            "notes": notes,
            "top_scale": int(top),     # the largest scale considered, after any box limit
        }
        return self

    def _training_rows(self, crops: list[np.ndarray], samples: Samples, top: int):
        """Features of sampled pixels inside the boxes, computed on each box's own crop
        (one per box of `samples`; windows never see past the box, so no other material
        leaks in)."""
        rng = np.random.default_rng(self.seed)
        X, y, names = [], [], []
        for label in samples.labels:
            rows = []
            for crop in [c for c, b in zip(crops, samples.boxes) if b.label == label]:
                feats, names = multiscale_features(crop, top, self.coherence)
                rows.append(feats.reshape(-1, feats.shape[-1]))
            rows = np.concatenate(rows)
            if rows.shape[0] < 4:
                raise ValueError(
                    f"material {samples.name_of(label)!r} (label {label}) has "
                    f"{rows.shape[0]} pixel(s) in its sample boxes; at least 4 are needed. "
                    "Draw larger boxes.")
            take = rng.choice(rows.shape[0], min(self.pixels_per_material, rows.shape[0]),
                              replace=False)
            X.append(rows[take])
            y.append(np.full(take.size, label, np.int64))
            self.class_means[int(label)] = float(rows[:, 0].mean())
        return np.concatenate(X).astype(np.float64), np.concatenate(y), names

    def _fit_levels(self, X: np.ndarray, y: np.ndarray, names: list[str]) -> None:
        levels = feature_levels(names)
        rng = np.random.default_rng(self.seed + 1)
        fold = rng.permutation(y.size) % 2
        self.levels, self.level_error = {}, {}
        for j in range(int(levels.max()) + 1):
            cols = np.flatnonzero(levels <= j)
            wrong = 0
            for f in (0, 1):            # 2-fold CV: train on one half, test on the other
                clf = GaussianClassifier(priors="equal").fit(X[fold == f][:, cols], y[fold == f])
                wrong += int(np.sum(clf.predict(X[fold != f][:, cols]) != y[fold != f]))
            self.level_error[j] = 100.0 * wrong / y.size
            self.levels[j] = GaussianClassifier(priors="equal").fit(X[:, cols], y)
        best = min(self.level_error.values())
        self.scale = min(j for j, e in self.level_error.items() if e <= best + self.tolerance)
        good = [j for j in range(self.scale + 1) if self.level_error[j] <= self.refine_error]
        self.finest_scale = min(good) if good else self.scale
        self.feature_names = [n for n, lv in zip(names, levels) if lv <= self.scale]

    def _fisher(self, X: np.ndarray, y: np.ndarray, names: list[str]) -> None:
        """Fisher ratio per feature: between-class over within-class variance."""
        means = np.stack([X[y == c].mean(axis=0) for c in self.labels])
        within = np.stack([X[y == c].var(axis=0) for c in self.labels]).mean(axis=0)
        ratio = means.var(axis=0) / np.maximum(within, 1e-300)      # constant features
        self.fisher = {n: float(r) for n, r in zip(names, ratio) if n in self.feature_names}

    # -- prediction ------------------------------------------------------------------------
    def _log_likelihood(self, feats: np.ndarray, level: int) -> np.ndarray:
        """(K, n) float32 log-likelihoods with priors (eq. 2.30) of feature rows, by the
        level's GM (rows in class-index order; the decision needs no float64)."""
        n = len(self.levels[level].offset_)            # levels are stacked in order
        return self.levels[level].log_likelihood(feats[:, :n], dtype=np.float32)

    def _predict_level(self, image: np.ndarray, level: int) -> np.ndarray:
        feats, _ = multiscale_features(image, level, self.coherence)
        ll = self._log_likelihood(feats.reshape(-1, feats.shape[-1]), level)
        return self._class_values()[argmax_first(ll)].reshape(image.shape)

    def _bias_field(self, base: np.ndarray, work: np.ndarray) -> np.ndarray:
        """Field of the standardised image `base` given the labels of its current
        correction `work` (both float32).

        Labelled by the cheapest good level (the finest refinement level); when that is
        the pixel value alone, only every few pixels are labelled, since the field is
        smooth anyway (this keeps it cheap on large volumes).
        """
        level = self.finest_scale
        step = max(1, min(base.shape) // FIELD_GRID) if level == 0 else 1
        sub = tuple(slice(None, None, step) for _ in base.shape)
        labels = self._predict_level(work[sub], level)
        field = estimate_bias_field(base[sub], labels, self.class_means, corrected=work[sub])
        return field if step == 1 else upsample_linear(field, base.shape)

    def _standardised(self, img: np.ndarray, field: np.ndarray | None = None,
                      out: np.ndarray | None = None) -> np.ndarray:
        """float32 ``(img - offset) / scale`` (divided by `field` if given), computed in
        float64 slab by slab: the one full-size array made from the image. `out` may be
        `field` itself (each slab is read before it is written)."""
        offset, scale = self.intensity
        out = np.empty(img.shape, np.float32) if out is None else out
        rows = max(1, _SLAB // max(1, int(np.prod(img.shape[1:]))))
        for i in range(0, img.shape[0], rows):
            x = img[i:i + rows].astype(np.float64)
            x -= offset
            x /= scale
            if field is not None:
                x /= field[i:i + rows]
            out[i:i + rows] = x
        return out

    def _classify(self, img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel log-likelihoods (K, ...) after refinement, and the level of each."""
        work = self._standardised(img)
        if self.bias_correction:
            base = work
            for _ in range(BIAS_ROUNDS):
                field = self._bias_field(base, work)
                work = np.divide(base, field, out=field)        # the field is spent
            del base, field
        return self._classify_standardised(work)

    def _classify_standardised(self, work: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_classify` of an image already standardised (and bias-corrected); every
        step is local, so a block with a margin of :func:`~._chunked.halo` px gives the
        whole image's result inside the margin. `work` may be overwritten."""
        shape = work.shape
        feats, _ = multiscale_features(work, self.scale, self.coherence)
        del work
        flat = feats.reshape(-1, feats.shape[-1])
        ll = self._log_likelihood(flat, self.scale)                 # (K, N)
        cls = argmax_first(ll).reshape(shape)
        level = np.full(shape, self.scale, np.int8)
        todo = np.ones(shape, bool)
        for j in range(self.scale, self.finest_scale, -1):
            w = window(j)
            # the level-j window of these pixels holds two labels: its statistics are mixed
            straddle = todo & (ndi.maximum_filter(cls, w) != ndi.minimum_filter(cls, w))
            idx = np.flatnonzero(straddle)
            if idx.size == 0:
                break
            ll[:, idx] = self._log_likelihood(flat[idx], j - 1)
            cls.ravel()[idx] = argmax_first(ll[:, idx])
            level.ravel()[idx] = j - 1
            todo = straddle
        return ll.reshape((-1,) + shape), level

    def predict_proba(self, image, *, check_input: bool = True
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Class probabilities after refinement and MRF, and the level each pixel used.

        Returns
        -------
        proba : (M, N[, P], K) ndarray of float32
            Probabilities of the materials in :attr:`labels` order.
        level : (M, N[, P]) ndarray of int8
            The scale whose classifier labelled each pixel (J, or finer at boundaries).
        """
        ll, level = self._classify(self.checked_image(image, check_input))
        proba = np.moveaxis(potts_mean_field(ll, self.beta), 0, -1)
        order = np.searchsorted(self._class_values(), self.label_values())
        return proba[..., order], level

    def predict(self, image, *, check_input: bool = True, return_level: bool = False):
        """Full-resolution labels, the input's shape (int32, int64 for labels >= 2^31).

        With ``return_level``: ``(labels, level)``, level as in :meth:`predict_proba`.
        """
        ll, level = self._classify(self.checked_image(image, check_input))
        labels = self._class_values()[potts_mean_field(ll, self.beta, labels_only=True)]
        return (labels, level) if return_level else labels

    def predict_tiles(self, image, *, check_input: bool = True) -> np.ndarray:
        """Majority label of every tile at :attr:`scale` (tile grid from index 0)."""
        return majority_tiles(self.predict(image, check_input=check_input), self.scale,
                              self.labels)

    def summary(self) -> dict:
        """Which scales and statistics drive the model (plain JSON)."""
        top = sorted(self.fisher.items(), key=lambda kv: -kv[1])[:_TOP_FEATURES]
        return {"method": self.method, "coarse_scale": self.scale,
                "finest_scale": self.finest_scale, "res_scale": self.res_scale,
                "level_error": {str(j): round(e, 3) for j, e in self.level_error.items()},
                "level_error_blocked": self.scores.get("level_error_blocked"),
                "window_px": {str(j): window(j) for j in self.scales},
                "top_features_fisher": {k: round(v, 4) for k, v in top},
                "beta": self.beta, "bias_correction": self.bias_correction}

    # -- file format -------------------------------------------------------------------
    def file_content(self) -> tuple[dict, dict[str, np.ndarray]]:
        """The JSON ``meta`` and the arrays :meth:`save` writes."""
        meta = {
            **self._common_meta(), "method": self.method,
            "scale": self.scale, "finest_scale": self.finest_scale,
            "res_scale": self.res_scale, "max_scale": self.max_scale,
            "feature_set": self.feature_set, "feature_names": self.feature_names,
            "coherence": self.coherence,
            "classifier": self.classifier_name,
            "options": {"tolerance": self.tolerance, "refine_error": self.refine_error,
                        "beta": self.beta, "bias_correction": self.bias_correction,
                        "pixels_per_material": self.pixels_per_material, "seed": self.seed},
            "class_means": {str(k): v for k, v in self.class_means.items()},
            "level_error": {str(k): v for k, v in self.level_error.items()},
            "fisher": self.fisher, "scores": self.scores,
            "intensity": {"offset": self.intensity[0], "scale": self.intensity[1]},
        }
        arrays = {f"level{j}_{k}": v for j, clf in self.levels.items()
                  for k, v in clf.fitted_arrays().items()}
        return meta, arrays

    @classmethod
    def from_file_content(cls, meta: dict, arrays: dict[str, np.ndarray]
                          ) -> RecommendedModel:
        """Rebuild from the ``meta`` dict and arrays of a saved file."""
        model = cls(max_scale=meta.get("max_scale"), **meta.get("options", {}))
        model._restore_common(meta)
        model.scale = int(meta["scale"])
        model.finest_scale = int(meta["finest_scale"])
        model.res_scale = meta.get("res_scale")
        model.feature_names = list(meta["feature_names"])
        # files saved before the coherence features neither name them nor say so
        model.coherence = bool(meta.get("coherence", False))
        model.class_means = {int(k): float(v) for k, v in meta["class_means"].items()}
        model.level_error = {int(k): float(v) for k, v in meta["level_error"].items()}
        model.fisher = dict(meta.get("fisher", {}))
        model.scores = meta.get("scores", {})
        intensity = meta.get("intensity", {"offset": 0.0, "scale": 1.0})
        model.intensity = (float(intensity["offset"]), float(intensity["scale"]))
        for j in model.level_error:
            prefix = f"level{j}_"
            fitted = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
            model.levels[j] = GaussianClassifier(priors="equal").set_fitted(fitted)
        return model


def _within_variance(values: np.ndarray, labels: np.ndarray) -> float:
    """Pooled within-class variance of `values`."""
    return float(sum(values[labels == c].var() * np.sum(labels == c)
                     for c in np.unique(labels)) / labels.size)
