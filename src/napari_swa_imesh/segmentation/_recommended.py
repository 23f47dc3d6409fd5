"""The recommended segmentation method: multi-scale SWA statistics per pixel, refined
coarse-to-fine at boundaries, regularised by a Potts MRF, with a smooth-bias correction.

Why each part is here (measured on the texture mosaics and 3-D tissue phantoms of
``benchmarks/bench_accuracy.py``; the reference's F1 + GM at one tile scale is kept in
:class:`~napari_swa_imesh.segmentation.SWAModel`):

* **Per-pixel statistics in sliding windows.** Tiles quantise every boundary to 2^j px.
  Here the statistics of scale j are taken in a centred window of ``2^j + 1`` px per axis
  around every pixel (separable box filters, O(N) per scale), so labels are full
  resolution and never shifted. Scale 0 is the pixel's own value.
* **Several scales at once.** Level j of the classifier sees every statistic of scales
  0..j: the window mean and log standard deviation (the first two SWA moments), and the
  log energy of the Haar detail coefficients of every finer level k < j in that window
  (the quantities the reference's entropy feature is built from; summed over axes, so
  rotation matters less). Skewness and kurtosis were measured to *hurt* on textures
  (window estimates too noisy), so they are left out.
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
* **Spatial regularisation.** A Potts MRF (beta 2) by five mean-field sweeps on the
  per-pixel log-likelihoods over the 2d face neighbours, vectorised over the pixels that
  are unsure or touch another label (no graph cut needed).
* **Smooth multiplicative bias** (MR-like data; EM-style, after Van Leemput et al. 1999):
  the field is the locally weighted least-squares ratio of the image to its class means,
  ``b = G*(I mu) / G*(mu^2)``, with G a wide Gaussian on a coarse grid; the image is divided
  by it and the classifiers refitted, twice; kept only where it helps (``"auto"``).

Explainability: :meth:`RecommendedModel.summary` lists the cross-validated error of every
level, the scales used (windows in px), and the features with the largest Fisher ratios;
:func:`plot_res_scales` shades the scales used on the RES plot.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from .._validation import as_image, label_dtype
from ..io import atomic_write
from ._classifiers import GaussianClassifier
from ._model_io import check_model_path, write_model_to
from ._samples import Material, Samples, check_contrast

__all__ = ["RecommendedModel", "multiscale_features", "multiscale_feature_names",
           "estimate_bias_field", "potts_mean_field", "plot_res_scales", "RECOMMENDED_METHOD"]

RECOMMENDED_METHOD = "recommended"
_CHUNK = 1 << 19        # pixels per likelihood batch (bounds float64 temporaries)
_LOG_FLOOR = 1e-12      # floor under variances/energies before the log (flat regions)


# -- features ----------------------------------------------------------------------------
def _box(x: np.ndarray, size: int) -> np.ndarray:
    """Mean over a centred box of odd `size` px per axis (separable, edges reflected)."""
    out = x
    for axis in range(x.ndim):
        out = ndi.uniform_filter1d(out, size, axis=axis, mode="reflect")
    return out


def _shifted(a: np.ndarray, offset: int, axis: int) -> np.ndarray:
    """``a[i + offset]`` along `axis`, repeating the edge value outside the array."""
    n = a.shape[axis]
    if offset == 0 or n == 1:
        return a.copy()
    k = min(abs(offset), n - 1)
    out = np.empty_like(a)

    def sl(start, stop):
        return (slice(None),) * axis + (slice(start, stop),)

    if offset > 0:
        out[sl(0, n - k)] = a[sl(k, n)]
        out[sl(n - k, n)] = a[sl(n - 1, n)]
    else:
        out[sl(k, n)] = a[sl(0, n - k)]
        out[sl(0, k)] = a[sl(0, 1)]
    return out


def _haar_energy(x: np.ndarray, level: int) -> np.ndarray:
    """Squared Haar detail of `level` summed over axes, centred on every pixel.

    The detail at pixel i along an axis is the mean of the s = 2^level pixels from i minus
    the mean of the s pixels before i (centred on i - 1/2); averaging its square at i and
    i + 1 centres it on i, so the feature does not shift boundaries. The image is mirrored
    by s pixels at both ends (as the box filters do), so flipping the image flips the
    feature exactly.
    """
    s = 1 << level
    energy = np.zeros(x.shape, np.float32)
    for axis in range(x.ndim):
        n = x.shape[axis]
        pad = [(0, 0)] * x.ndim
        pad[axis] = (s, s)
        # running sums in float64: block means of large-offset data stay exact enough
        c = np.cumsum(np.pad(x, pad, mode="symmetric"), axis=axis, dtype=np.float64)
        c = np.concatenate([np.zeros_like(np.take(c, [0], axis=axis)), c], axis=axis)

        def part(a, start, stop):
            return a[(slice(None),) * axis + (slice(start, stop),)]

        # block[m] = mean of the s pixels from original index m - s, m = 0 .. n + s
        block = (part(c, s, n + 2 * s + 1) - part(c, 0, n + s + 1)) / s
        d = (part(block, s, n + s + 1) - part(block, 0, n + 1)).astype(np.float32)
        d *= d                                   # (n + 1) squared details, at i - 1/2
        energy += 0.5 * (part(d, 0, n) + part(d, 1, n + 1))
    return energy


def multiscale_feature_names(max_scale: int) -> list[str]:
    """Names of the features of levels 0..max_scale, in stack order.

    Examples
    --------
    >>> multiscale_feature_names(2)
    ['value', 'mean@1', 'logstd@1', 'haar0@1', 'mean@2', 'logstd@2', 'haar0@2', 'haar1@2']
    """
    names = ["value"]
    for j in range(1, max_scale + 1):
        names += [f"mean@{j}", f"logstd@{j}"] + [f"haar{k}@{j}" for k in range(j)]
    return names


def _feature_levels(names: list[str]) -> np.ndarray:
    return np.array([0 if n == "value" else int(n.split("@")[1]) for n in names])


def multiscale_features(image, max_scale: int) -> tuple[np.ndarray, list[str]]:
    """Per-pixel SWA statistics in centred windows of 2^j + 1 px, for j = 0..max_scale.

    Parameters
    ----------
    image : (M, N[, P]) array_like
        Grey-level image.
    max_scale : int
        Largest scale (window of ``2**max_scale + 1`` px per axis).

    Returns
    -------
    features : (M, N[, P], F) ndarray of float32
        Channel-last stack; F = 1 + sum_j (2 + j). Scale 0 is the pixel value; scale j
        adds the window mean, the log standard deviation and the log mean energy of the
        Haar details of levels k < j (all O(N) box filters).
    names : list of str
        ``value``, ``mean@j``, ``logstd@j``, ``haar{k}@j``.
    """
    x = np.asarray(image, dtype=np.float32)
    names = multiscale_feature_names(max_scale)
    out = np.empty(x.shape + (len(names),), np.float32)
    out[..., 0] = x
    energies = [_haar_energy(x, k) for k in range(max_scale)]
    c = 1
    for j in range(1, max_scale + 1):
        w = (1 << j) + 1
        mean = _box(x, w)
        var = _box(x * x, w) - mean * mean
        out[..., c] = mean
        out[..., c + 1] = 0.5 * np.log(np.maximum(var, _LOG_FLOOR))
        c += 2
        for k in range(j):
            out[..., c] = 0.5 * np.log(np.maximum(_box(energies[k], w), _LOG_FLOOR))
            c += 1
    return out, names


# -- bias field and MRF --------------------------------------------------------------------
def _upsample_linear(small: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Separable linear interpolation of a coarse grid (cell centres) onto `shape`."""
    out = small
    for axis, n in enumerate(shape):
        m = small.shape[axis]
        pos = np.clip((np.arange(n) + 0.5) * m / n - 0.5, 0, m - 1)
        lo = np.floor(pos).astype(np.intp)
        hi = np.minimum(lo + 1, m - 1)
        w = (pos - lo).astype(np.float32).reshape((-1,) + (1,) * (len(shape) - axis - 1))
        out = np.take(out, lo, axis=axis) * (1 - w) + np.take(out, hi, axis=axis) * w
    return out


def _block_mean(a: np.ndarray, factor: int) -> np.ndarray:
    """Mean over blocks of `factor` px per axis (partial blocks at the far edge included)."""
    out = a
    for axis in range(a.ndim):
        n = out.shape[axis]
        starts = np.arange(0, n, factor)
        out = np.add.reduceat(out, starts, axis=axis) / np.diff(
            np.append(starts, n)).reshape((-1,) + (1,) * (a.ndim - axis - 1))
    return out


def estimate_bias_field(image, labels, class_means: dict[int, float], *,
                        smoothness: float = 0.15) -> np.ndarray:
    """Smooth multiplicative bias b with ``image ~ b * mean(label)``.

    Locally weighted least squares: ``b = G*(I mu) / G*(mu^2)`` where mu is the class mean
    of each pixel's label and G a Gaussian of ``smoothness`` times the smallest image side,
    computed on a grid about 32 cells across (the field is smooth by assumption) and
    interpolated back.

    Parameters
    ----------
    image : (M, N[, P]) ndarray
    labels : (M, N[, P]) ndarray of int
    class_means : dict of int to float
        Mean intensity of every label.
    smoothness : float

    Returns
    -------
    (M, N[, P]) ndarray of float32
        The field (1 where the image matches the class means).
    """
    keys = np.array(sorted(class_means))                 # labels may be any 63-bit value
    values = np.array([class_means[k] for k in keys], np.float32)
    mu = values[np.minimum(np.searchsorted(keys, labels), keys.size - 1)]
    factor = max(1, min(image.shape) // 32)
    num = _block_mean(np.asarray(image, np.float32) * mu, factor)
    den = _block_mean(mu * mu, factor)
    sigma = smoothness * min(num.shape)
    num = ndi.gaussian_filter(num, sigma, mode="nearest")
    den = ndi.gaussian_filter(den, sigma, mode="nearest")
    field = num / np.maximum(den, 1e-12 * max(float(den.max()), 1e-30))
    field = np.where(field > 0, field, 1.0).astype(np.float32)
    return _upsample_linear(field, image.shape).astype(np.float32)


def potts_mean_field(log_likelihood: np.ndarray, beta: float, iterations: int = 5, *,
                     confident: float = 1e-3, labels_only: bool = False) -> np.ndarray:
    """Mean-field Potts regularisation of per-pixel class log-likelihoods.

    ``q_k <- softmax(L_k + beta * sum over the 2d face neighbours of q_k)``, `iterations`
    sweeps, vectorised over the *active* pixels: those whose best class leads the second
    by less than ``log((1 - confident) / confident)`` or that touch another label, grown
    by one pixel. The others are sure and agree with every neighbour, so the MRF could only
    confirm them: they enter their neighbours' sums as their label's indicator (this keeps
    256^3 volumes within seconds).

    Parameters
    ----------
    log_likelihood : (K, M, N[, P]) ndarray of float32
        Class-first (reductions over a short last axis are slow in numpy).
    beta : float
        Coupling: the log-odds one agreeing neighbour adds (0: no smoothing).
    iterations : int
    confident : float
    labels_only : bool
        Return the class index of every pixel instead of the probabilities.

    Returns
    -------
    (K, M, N[, P]) ndarray of float32, or (M, N[, P]) ndarray of int8
        Class probabilities, or the most probable class index.
    """
    k, shape = log_likelihood.shape[0], log_likelihood.shape[1:]
    cls = _argmax_first(log_likelihood)
    if beta <= 0 or iterations <= 0:
        return cls if labels_only else _softmax_first(log_likelihood)
    active = _lead(log_likelihood) < np.log((1 - confident) / confident)
    active |= _touches_other(cls)
    active |= _touches_other(active)                      # grow by one pixel
    coords = np.nonzero(active)
    del active
    idx = np.ravel_multi_index(coords, shape)             # sorted: nonzero is row-major
    ll = log_likelihood.reshape(k, -1)[:, idx]            # (K, A)
    q = _softmax_first(ll)
    flat_cls = cls.ravel()
    neighbours = []                                       # per direction: (pos, active, fixed)
    strides = np.cumprod((1,) + shape[::-1])[:-1][::-1]
    for axis, st in enumerate(strides):
        for step, inside in ((-st, coords[axis] > 0), (st, coords[axis] < shape[axis] - 1)):
            nbr = np.where(inside, idx + step, idx)
            pos = np.minimum(np.searchsorted(idx, nbr), idx.size - 1)
            act = inside & (idx[pos] == nbr)
            fixed = np.zeros((k, idx.size), np.float32)   # outside the image: nothing
            rest = np.flatnonzero(inside & ~act)
            fixed[flat_cls[nbr[rest]], rest] = 1.0
            neighbours.append((pos, act.astype(np.float32), fixed))
    del coords
    for _ in range(iterations):
        nb = np.zeros_like(q)
        for pos, act, fixed in neighbours:
            nb += q[:, pos] * act
            nb += fixed
        q = _softmax_first(ll + beta * nb)
    if labels_only:
        flat_cls[idx] = _argmax_first(q)
        return cls
    out = _softmax_first(log_likelihood)
    out.reshape(k, -1)[:, idx] = q
    return out


def _lead(a: np.ndarray) -> np.ndarray:
    """Best minus second-best value over the first axis (elementwise, a few classes)."""
    best = np.maximum(a[0], a[1])
    second = np.minimum(a[0], a[1])
    for k in range(2, a.shape[0]):
        second = np.maximum(second, np.minimum(best, a[k]))
        best = np.maximum(best, a[k])
    return best - second


def _softmax_first(a: np.ndarray) -> np.ndarray:
    e = np.exp(a - a.max(axis=0))
    e /= e.sum(axis=0)
    return e


def _argmax_first(a: np.ndarray) -> np.ndarray:
    """argmax over the first axis by elementwise comparisons (fast for a few classes)."""
    best = a[0].copy()
    out = np.zeros(a.shape[1:], np.int8)
    for k in range(1, a.shape[0]):
        better = a[k] > best
        out[better] = k
        np.maximum(best, a[k], out=best)
    return out


def _touches_other(values: np.ndarray) -> np.ndarray:
    """Pixels with a face neighbour of another value (elementwise, no window filter)."""
    out = np.zeros(values.shape, bool)
    for axis in range(values.ndim):
        lo = (slice(None),) * axis + (slice(None, -1),)
        hi = (slice(None),) * axis + (slice(1, None),)
        diff = values[lo] != values[hi]
        out[lo] |= diff
        out[hi] |= diff
    return out


# -- the model -----------------------------------------------------------------------------
class RecommendedModel:
    """Multi-scale per-pixel SWA classifier with boundary refinement, MRF and bias correction.

    See the module docstring for the method. Fitted attributes follow :class:`SWAModel`
    where they mean the same thing, so code written for it (and the model file) keeps
    working: ``scale`` is the coarse level J, ``materials``, ``feature_names`` (of level
    J), ``ndim``, ``spacing``, ``scores``.

    Parameters
    ----------
    max_scale : int, optional
        Largest scale considered; default the suggested RES of the samples (capped at 6).
    tolerance : float
        Coarse level: the smallest whose cross-validated error (percent) is within this
        of the best level's.
    refine_error : float
        Boundary refinement goes down to the finest level with at most this error (percent).
    beta : float
        Potts coupling of the MRF (0: off).
    bias_correction : bool or "auto"
        Estimate and remove a smooth multiplicative intensity bias. "auto" keeps the
        correction only when it shrinks the within-material variance of the pixel values
        in the sample boxes by at least 1 % (measured: 1.6-3 % on phantoms with 20-40 %
        bias, 0.2-0.6 % without bias, negative on texture mosaics, where it would only
        add noise and time).
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
        if max_scale is not None and not 0 <= int(max_scale) <= 8:
            raise ValueError(f"max_scale must be 0..8 (windows up to 257 px); got {max_scale}.")
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

    @property
    def labels(self) -> list[int]:
        return [m.label for m in self.materials]

    def label_values(self) -> np.ndarray:
        """Material labels in :attr:`labels` order, in a dtype that holds them."""
        return np.asarray(self.labels, label_dtype(self.labels))

    @property
    def scales(self) -> list[int]:
        """Levels the labels can come from: coarse level J down to the finest refinement."""
        return list(range(self.scale, self.finest_scale - 1, -1))

    # -- fitting ---------------------------------------------------------------------------
    def fit(self, image, samples: Samples, *, spacing=None, res_scale: int | None = None
            ) -> "RecommendedModel":
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
        """
        img = as_image(image)
        samples.check(img.shape)
        check_contrast(img, samples)
        if res_scale is None and self.max_scale is None:
            from ._res import res_statistics

            res_scale = res_statistics(img, samples).suggested_scale
        self.res_scale = res_scale
        top = self.max_scale if self.max_scale is not None else min(
            6, res_scale if res_scale is not None else 2)
        limit = samples.window_limit(top)
        if limit is not None:
            # box sizes are the user's, not the image's: a level no box of some material
            # can train is never used (the scale is a maximum), and the user hears which
            # box to enlarge
            warnings.warn(f"{limit[1]}; using scales up to {limit[0]}.", UserWarning,
                          stacklevel=2)
            top = limit[0]
        self.materials = list(samples.materials)
        self.ndim = img.ndim
        self.spacing = None if spacing is None else tuple(float(s) for s in spacing)
        # intensities in units of the boxes' spread above the image minimum: every result
        # is invariant to x -> a x + b (a > 0), and the bias stays multiplicative
        inside = np.concatenate([img[b.slices].ravel() for b in samples.boxes])
        self.intensity = (float(img.min()), float(inside.std()) or float(img.std()))
        img = self._standardise(img)
        work = img.astype(np.float32)
        field = None
        rounds = 3 if self.bias_correction else 1
        first = None
        for r in range(rounds):
            # the first round picks the levels; the bias rounds refit only the level that
            # labels the image for the field, the last round refits every level
            X, y, names = self._training_rows(work, samples, top if r in (0, rounds - 1)
                                              else self.finest_scale)
            if r in (0, rounds - 1):
                self._fit_levels(X, y, names)
                if r == 0:
                    first = (X, y, names, dict(self.class_means))
            else:
                self.levels[self.finest_scale] = GaussianClassifier(priors="equal").fit(X, y)
            if r + 1 < rounds:
                field = self._bias_field(img, work)
                # keep the intensity scale of the training boxes: b = 1 on them on average
                inside = np.zeros(img.shape, bool)
                for b in samples.boxes:
                    inside[b.slices] = True
                field /= np.float32(np.median(field[inside]))
                work = (img / field).astype(np.float32)
        reduction = None
        if rounds > 1:
            reduction = 1.0 - _within_variance(X[:, 0], y) / max(
                _within_variance(first[0][:, 0], first[1]), 1e-300)
            if self.bias_correction == "auto" and reduction < 0.01:
                X, y, names, self.class_means = first
                self._fit_levels(X, y, names)
                field = None
        if self.bias_correction == "auto":
            self.bias_correction = field is not None
        self._fisher(X, y, names)
        err = self.level_error[self.scale]
        self.scores = {
            "eps_l": err, "eps_l_method": "2-fold cross-validation over sampled pixels of the "
                                          "boxes (pixels are correlated: optimistic)",
            "eps_m": -len(self.feature_names) * err / 100.0,
            "training_pixels": {int(m): int(np.sum(y == m)) for m in samples.labels},
            "level_error": {str(j): e for j, e in self.level_error.items()},
            "regularized": sorted({int(c) for clf in self.levels.values()
                                   for c, reg in zip(clf.classes_, clf.regularized_) if reg}),
            "bias_correction": bool(self.bias_correction),
            "bias_variance_reduction": reduction,
            "bias_range": None if field is None else [float(field.min()), float(field.max())],
        }
        return self

    def _training_rows(self, image: np.ndarray, samples: Samples, top: int):
        """Features of sampled pixels inside the boxes, computed on each box's own crop
        (windows never see past the box, so no other material leaks in)."""
        rng = np.random.default_rng(self.seed)
        X, y, names = [], [], []
        for label in samples.labels:
            rows = []
            for box in samples.boxes_of(label):
                feats, names = multiscale_features(image[box.slices], top)
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
        levels = _feature_levels(names)
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
        ratio = means.var(axis=0) / np.maximum(within, 1e-300)
        self.fisher = {n: float(r) for n, r in zip(names, ratio) if n in self.feature_names}

    # -- prediction ------------------------------------------------------------------------
    def _log_likelihood(self, feats: np.ndarray, level: int) -> np.ndarray:
        """(K, n) float32 log-likelihoods (with priors, eq. 2.30) of feature rows.

        The level's GM in float32 with the inverse Cholesky factors precomputed: one small
        matrix product per class and batch (the decision needs no float64 here).
        """
        clf = self.levels[level]
        n = len(multiscale_feature_names(level))     # levels are stacked in order
        inv = np.linalg.inv(clf.cholesky_).astype(np.float32)          # (K, p, p)
        shift = np.einsum("kij,kj->ki", inv, clf.means_).astype(np.float32)
        const = (-0.5 * clf.logdet_ + np.log(clf.priors_)).astype(np.float32)
        offset = clf.offset_.astype(np.float32)
        scale = (1.0 / clf.scale_).astype(np.float32)
        # rows follow self.labels (the materials' order), not the classifier's sorted classes
        row = [self.labels.index(int(c)) for c in clf.classes_]
        out = np.empty((clf.classes_.size, feats.shape[0]), np.float32)
        for i in range(0, feats.shape[0], _CHUNK):
            z = (feats[i:i + _CHUNK, :n] - offset) * scale
            for c in range(clf.classes_.size):
                w = z @ inv[c].T - shift[c]
                out[row[c], i:i + _CHUNK] = const[c] - 0.5 * np.einsum("ij,ij->i", w, w)
        return out

    def _predict_level(self, image: np.ndarray, level: int) -> np.ndarray:
        feats, _ = multiscale_features(image, level)
        ll = self._log_likelihood(feats.reshape(-1, feats.shape[-1]), level)
        return self.label_values()[_argmax_first(ll)].reshape(image.shape)

    def _bias_field(self, image: np.ndarray, work: np.ndarray) -> np.ndarray:
        """Field of `image` given the labels of its current correction `work`.

        Labelled by the cheapest good level (the finest refinement level); when that is
        the pixel value alone, only every few pixels are labelled, since the field is
        smooth anyway (this keeps it cheap on large volumes).
        """
        level = self.finest_scale
        step = max(1, min(image.shape) // 64) if level == 0 else 1
        sub = tuple(slice(None, None, step) for _ in image.shape)
        labels = self._predict_level(work[sub], level)
        field = estimate_bias_field(image[sub], labels, self.class_means)
        return field if step == 1 else _upsample_linear(field, image.shape)

    def _corrected(self, image) -> tuple[np.ndarray, np.ndarray | None]:
        """The (standardised) image divided by its estimated bias field (float32), and
        the field."""
        img = np.asarray(image, np.float32)
        if not self.bias_correction:
            return img, None
        work, field = img, None
        for _ in range(2):
            field = self._bias_field(img, work)
            work = img / field
        return work.astype(np.float32), field

    def _labels_and_ll(self, img: np.ndarray):
        """Refined labels, per-pixel log-likelihoods and level (before the MRF)."""
        work, _ = self._corrected(img)
        feats, _ = multiscale_features(work, self.scale)
        del work
        flat = feats.reshape(-1, feats.shape[-1])
        ll = self._log_likelihood(flat, self.scale)                 # (K, N)
        cls = _argmax_first(ll).reshape(img.shape)
        level = np.full(img.shape, self.scale, np.int8)
        todo = np.ones(img.shape, bool)
        for j in range(self.scale, self.finest_scale, -1):
            w = (1 << j) + 1
            # the level-j window of these pixels holds two labels: its statistics are mixed
            straddle = todo & (ndi.maximum_filter(cls, w) != ndi.minimum_filter(cls, w))
            idx = np.flatnonzero(straddle)
            if idx.size == 0:
                break
            ll[:, idx] = self._log_likelihood(flat[idx], j - 1)
            cls.ravel()[idx] = _argmax_first(ll[:, idx])
            level.ravel()[idx] = j - 1
            todo = straddle
        return ll.reshape((-1,) + img.shape), level

    def predict_proba(self, image) -> tuple[np.ndarray, np.ndarray]:
        """Class probabilities after refinement and MRF, and the level each pixel used.

        Returns
        -------
        proba : (M, N[, P], K) ndarray of float32
            Probabilities of the materials in :attr:`labels` order.
        level : (M, N[, P]) ndarray of int8
            The scale whose classifier labelled each pixel (J, or finer at boundaries).
        """
        ll, level = self._labels_and_ll(self._check_image(image))
        return np.moveaxis(potts_mean_field(ll, self.beta), 0, -1), level

    def predict(self, image) -> np.ndarray:
        """Full-resolution labels, the input's shape (int32, int64 for labels >= 2^31)."""
        ll, _ = self._labels_and_ll(self._check_image(image))
        return self.label_values()[potts_mean_field(ll, self.beta,
                                                                  labels_only=True)]

    def predict_tiles(self, image) -> np.ndarray:
        """Majority label of every tile at :attr:`scale` (tile grid from index 0)."""
        return majority_tiles(self.predict(image), self.scale, self.labels)

    def _check_image(self, image) -> np.ndarray:
        """The image, checked and standardised like the training image (a new array)."""
        if not self.materials:
            raise ValueError("this model is not fitted; call fit() or load a saved model.")
        img = as_image(image)
        if img.ndim != self.ndim:
            raise ValueError(
                f"the model was fitted on {self.ndim}-D images; got a {img.ndim}-D image.")
        check_contrast(img)
        return self._standardise(img)

    def _standardise(self, img: np.ndarray) -> np.ndarray:
        """``(img - offset) / scale`` in place on a float64 array of our own."""
        offset, scale = self.intensity
        img -= offset
        img /= scale
        return img

    def summary(self) -> dict:
        """Which scales and statistics drive the model (plain JSON)."""
        top = sorted(self.fisher.items(), key=lambda kv: -kv[1])[:8]
        return {"method": self.method, "coarse_scale": self.scale,
                "finest_scale": self.finest_scale, "res_scale": self.res_scale,
                "level_error": {str(j): round(e, 3) for j, e in self.level_error.items()},
                "window_px": {str(j): (1 << j) + 1 if j else 1 for j in self.scales},
                "top_features_fisher": {k: round(v, 4) for k, v in top},
                "beta": self.beta, "bias_correction": self.bias_correction}

    # -- file format -------------------------------------------------------------------
    def save(self, path, *, force: bool = False) -> Path:
        """Write NPZ arrays + JSON ``meta`` (``method``: "recommended"; no pickles)."""
        check_model_path(path)
        with atomic_write([path], force=force) as (tmp,):
            write_model_to(tmp, *self.file_content())
        return Path(path)

    def file_content(self) -> tuple[dict, dict[str, np.ndarray]]:
        """The JSON ``meta`` and the arrays :meth:`save` writes."""
        from .. import __version__

        meta = {
            "method": self.method, "version": __version__,
            "scale": self.scale, "finest_scale": self.finest_scale,
            "res_scale": self.res_scale, "max_scale": self.max_scale,
            "feature_set": self.feature_set, "feature_names": self.feature_names,
            "classifier": self.classifier_name, "ndim": self.ndim, "spacing": self.spacing,
            "materials": [{"label": m.label, "name": m.name, "color": m.color}
                          for m in self.materials],
            "options": {"tolerance": self.tolerance, "refine_error": self.refine_error,
                        "beta": self.beta, "bias_correction": self.bias_correction,
                        "pixels_per_material": self.pixels_per_material, "seed": self.seed},
            "class_means": {str(k): v for k, v in self.class_means.items()},
            "level_error": {str(k): v for k, v in self.level_error.items()},
            "fisher": self.fisher, "scores": self.scores,
            "intensity": {"offset": self.intensity[0], "scale": self.intensity[1]},
        }
        arrays = {f"level{j}_{k}": v for j, clf in self.levels.items()
                  for k, v in clf.get_params().items()}
        return meta, arrays

    @classmethod
    def from_saved(cls, meta: dict, arrays: dict[str, np.ndarray]) -> "RecommendedModel":
        """Rebuild from the ``meta`` dict and arrays of a saved file (see :meth:`save`)."""
        model = cls(max_scale=meta.get("max_scale"), **meta.get("options", {}))
        model.scale = int(meta["scale"])
        model.finest_scale = int(meta["finest_scale"])
        model.res_scale = meta.get("res_scale")
        model.feature_names = list(meta["feature_names"])
        model.ndim = int(meta["ndim"])
        model.spacing = tuple(meta["spacing"]) if meta.get("spacing") else None
        model.materials = [Material(int(m["label"]), m["name"], m.get("color"))
                           for m in meta["materials"]]
        model.class_means = {int(k): float(v) for k, v in meta["class_means"].items()}
        model.level_error = {int(k): float(v) for k, v in meta["level_error"].items()}
        model.fisher = dict(meta.get("fisher", {}))
        model.scores = meta.get("scores", {})
        intensity = meta.get("intensity", {"offset": 0.0, "scale": 1.0})
        model.intensity = (float(intensity["offset"]), float(intensity["scale"]))
        for j in model.level_error:
            prefix = f"level{j}_"
            params = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
            model.levels[j] = GaussianClassifier().set_params(params)
        return model


def plot_res_scales(stats, scales, *, figure=None, dark: bool = False):
    """The RES plot (:func:`plot_res`) with the scales a segmentation used shaded.

    The coarse scale is the solid line (``selected_scale``), the band from the finest
    refinement scale to it is shaded green, and the suggested RES stays dashed red, so the
    user sees where the classifier's scales sit on the statistics they came from.

    Parameters
    ----------
    stats : ResStatistics
    scales : sequence of int
        E.g. ``result.scales`` (coarse first).
    figure : matplotlib.figure.Figure, optional
    dark : bool

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ._res import plot_res

    scales = [int(j) for j in scales]
    fig = plot_res(stats, figure=figure, selected_scale=max(scales), dark=dark)
    for ax in fig.axes:
        ax.axvspan(min(scales) - 0.25, max(scales) + 0.25, color="#2ca02c", alpha=0.12, lw=0)
    fig.suptitle(f"{fig._suptitle.get_text()}; scales used: "
                 f"{', '.join(map(str, scales))}", fontsize=10,
                 color=fig._suptitle.get_color())
    return fig


def _within_variance(values: np.ndarray, labels: np.ndarray) -> float:
    """Pooled within-class variance of `values`."""
    return float(sum(values[labels == c].var() * np.sum(labels == c)
                     for c in np.unique(labels)) / labels.size)


def majority_tiles(labels: np.ndarray, scale: int, materials: list[int]) -> np.ndarray:
    """Most frequent label in every tile of 2^scale px per axis (last tiles may be partial).

    Returns
    -------
    (ceil(M/2^scale), ceil(N/2^scale)[, ...]) ndarray of int32

    Examples
    --------
    >>> majority_tiles(np.array([[1, 1, 2], [1, 2, 2]]), 1, [1, 2]).tolist()
    [[1, 2]]
    """
    dtype = label_dtype(materials)
    if scale == 0:
        return np.asarray(labels, dtype).copy()
    s = 1 << scale
    counts = np.stack([_block_sum(labels == m, s) for m in materials])
    return np.asarray(materials, dtype)[counts.argmax(axis=0)]


def _block_sum(mask: np.ndarray, s: int) -> np.ndarray:
    """Count of True per block of s px per axis (zero-padded at the far edges)."""
    tiles = tuple(-(-n // s) for n in mask.shape)
    padded = np.zeros(tuple(t * s for t in tiles), np.uint8)
    padded[tuple(slice(0, n) for n in mask.shape)] = mask
    blocks = padded.reshape(tuple(v for t in tiles for v in (t, s)))
    return blocks.sum(axis=tuple(range(1, 2 * mask.ndim, 2)), dtype=np.int32)
