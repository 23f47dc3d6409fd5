"""Smooth multiplicative bias field (MR-like data; EM-style, after Van Leemput et al. 1999).

The field is a low-order polynomial of ``log(image / class mean)`` (as the parametric
bias models of Van Leemput et al. 1999 and Styner et al. 2000), fitted robustly to the
least-squares ratios ``sum(I mu) / sum(mu^2)`` of the cells of a coarse grid, of the degree
that predicts held-out cells best; degree 0 (no field) unless the evidence says otherwise.
A Gaussian-weighted local ratio (the estimator before) followed tissue composition at low
noise: fields of 0.57..1.09 on images without bias, costing WM Dice up to .16.

Only *inliers* enter the sums: pixels whose local mean (5-px window of the currently
corrected image) is within half the smallest gap between class means of their own class
mean (so it is nearer that mean than any other). Background that no material describes
(dark air around an MR head, labelled as the darkest material) and partial-volume
boundaries would otherwise pull the field
(measured on the real-anatomy phantoms: a field of 0.1..1.08 on an image with no bias).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ._tiles import block_mean, block_sum

__all__ = ["estimate_bias_field", "upsample_linear", "upsample_linear_at", "GRID_CELLS",
           "grid_factor", "class_mean_image", "coarse_bias_field", "field_terms",
           "INLIER_GAP", "LOCAL_WINDOW"]

GRID_CELLS = 32         # coarse grid: about this many cells along the shortest side
_TINY = 1e-12           # relative floor under G*(mu^2) (regions of class mean 0)
_NONE = 1e-30           # floor of that floor when every class mean is 0
INLIER_GAP = 0.5        # inlier: local mean within this fraction of the smallest class gap
#                         (0.5 against 0.25: +0.01 GM/WM Dice on the dev anatomy split)
LOCAL_WINDOW = 5        # px per axis of that local mean (2 px reach)
_SLAB = 1 << 20         # float64 values per slab of an upsampling (8 MB)
FIT_CELLS = 12          # cells along the shortest side of the polynomial fit
MAX_DEGREE = 3          # log-field: polynomial of total degree <= 3 (20 terms in 3-D)
CV_BLOCKS = 4           # checkerboard blocks per side of the degree's cross-validation
EVIDENCE = 3.0          # z of the held-out gain a field needs (one-sided p ~ 0.1 %)
_HUBER = 1.345          # Huber threshold in robust sigmas (95 % efficiency)
_IRLS = 8               # reweighting rounds


def upsample_linear(small: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Linear interpolation of a coarse grid onto `shape`, cell centre to cell centre
    (``grid_mode``), edge values held beyond the outer centres; float32 in, float32 out.

    ``scipy.ndimage.zoom(small, ..., order=1, mode="nearest", grid_mode=True)`` to within
    one float32 ulp (bit-identical for whole-number factors; tests), in about a quarter of
    its time on a full-size 3-D field; and :func:`upsample_linear_at` over the whole grid
    exactly (the same code).
    """
    return upsample_linear_at(small, shape, [np.arange(n) for n in shape])


def estimate_bias_field(image, labels, class_means: dict[int, float], *,
                        max_degree: int = MAX_DEGREE, corrected=None) -> np.ndarray:
    """Smooth multiplicative bias b with ``image ~ b * mean(label)``, or exactly 1.

    The inlier pixels' sums of ``I mu`` and ``mu^2`` per cell of a grid about
    :data:`GRID_CELLS` cells across give each cell's least-squares ratio; ``log b`` is a
    low-order polynomial fitted robustly to those ratios, of the degree that predicts
    held-out cells best (:func:`coarse_bias_field`; degree 0: no field). The field
    cannot follow tissue edges (it has at most ``comb(d + max_degree, d)`` degrees of
    freedom over the whole image) and is 1 unless it is supported by held-out evidence.

    Parameters
    ----------
    image : (M, N[, P]) ndarray
    labels : (M, N[, P]) ndarray of int
    class_means : dict of int to float
        Mean intensity of every label.
    max_degree : int
        Largest total degree of the polynomial of ``log b``.
    corrected : (M, N[, P]) ndarray, optional
        The image as currently corrected (the labels' source), for the inlier test;
        default `image`.

    Returns
    -------
    (M, N[, P]) ndarray of float32
        The field (geometric mean 1 over the inliers; all 1 when no field is supported).

    Examples
    --------
    >>> labels = np.repeat([[1] * 8 + [2] * 8], 16, axis=0)
    >>> image = np.where(labels == 1, 1.0, 2.0)
    >>> bool(np.all(estimate_bias_field(image, labels, {1: 1.0, 2: 2.0}) == 1))
    True
    """
    image = np.asarray(image, np.float32)
    num, den = field_terms(image, image if corrected is None else corrected, labels,
                           class_means)
    factor = grid_factor(image.shape)
    num, den = block_mean(num, factor), block_mean(den, factor)
    return upsample_linear(coarse_bias_field(num, den, max_degree), image.shape)


def field_terms(image: np.ndarray, corrected: np.ndarray, labels: np.ndarray,
                class_means: dict[int, float]) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ``I mu`` and ``mu^2`` (float32), zero outside the inliers (module
    docstring); `image` is the uncorrected I, `corrected` the image the labels came from."""
    mu = class_mean_image(labels, class_means)
    mu = np.where(_inliers(corrected, mu, class_means), mu, np.float32(0))
    return image * mu, mu * mu


def _inliers(corrected: np.ndarray, mu: np.ndarray, class_means: dict[int, float]
             ) -> np.ndarray:
    """Pixels whose local mean is within :data:`INLIER_GAP` of the smallest class gap of
    their class mean `mu`."""
    means = np.sort(np.fromiter(class_means.values(), float))
    gap = float(np.diff(means).min()) if means.size > 1 else float(abs(means[0]))
    local = ndi.uniform_filter(np.asarray(corrected, np.float32), LOCAL_WINDOW,
                               mode="reflect")
    return np.abs(local - mu) <= INLIER_GAP * gap


def inlier_sums(image: np.ndarray, labels: np.ndarray, class_means: dict[int, float]
                ) -> dict[int, tuple[float, int]]:
    """Sum and count of the inlier pixels of every label (the pixels
    :func:`field_terms` counts), for class means that match those pixels."""
    keep = _inliers(image, class_mean_image(labels, class_means), class_means)
    image = np.asarray(image, np.float64)
    return {k: (float(image[keep & (labels == k)].sum()),
                int(np.count_nonzero(keep & (labels == k)))) for k in class_means}


def grid_factor(shape: tuple[int, ...]) -> int:
    """Pixels per side of a cell of the coarse grid the field is estimated on."""
    return max(1, min(shape) // GRID_CELLS)


def class_mean_image(labels: np.ndarray, class_means: dict[int, float]) -> np.ndarray:
    """float32 class mean of every pixel's label."""
    keys = np.array(sorted(class_means))                 # labels may be any 63-bit value
    values = np.array([class_means[k] for k in keys], np.float32)
    return values[np.minimum(np.searchsorted(keys, labels), keys.size - 1)]


def coarse_bias_field(num: np.ndarray, den: np.ndarray, max_degree: int = MAX_DEGREE
                      ) -> np.ndarray:
    """The field on the coarse grid from the cell means of ``I mu`` and ``mu^2`` (float32).

    ``log b`` is a polynomial of total degree 0..`max_degree` in the cell coordinates,
    fitted by robust (Huber) weighted least squares to the cells' ``log(num / den)``
    (weights `den`: the cell's inlier count times mu^2). The degree is chosen by evidence:
    2-fold cross-validation over a checkerboard of blocks of cells (:data:`CV_BLOCKS`
    per side); degree 0 wins unless a smooth field predicts held-out blocks better, and
    then the field is exactly 1 (so a flat-field image is never "corrected"). A field
    is scaled to weighted geometric mean 1 over the cells: it redistributes intensity,
    it does not rescale the image.
    """
    shape = np.shape(num)
    # the fit needs no more than FIT_CELLS cells along the shortest side (the field has
    # at most 20 degrees of freedom): sums over blocks of cells, centres in cell units
    f = max(1, min(shape) // FIT_CELLS)
    num_s = block_sum(np.asarray(num, np.float64), f, dtype=np.float64)
    den_s = block_sum(np.asarray(den, np.float64), f, dtype=np.float64)
    centres = [np.minimum(np.arange(m) * f + f / 2, (np.arange(m) * f + n) / 2)
               for m, n in zip(num_s.shape, shape)]
    ok = ((den_s > _TINY * max(float(den_s.max(initial=0.0)), _NONE)) & (num_s > 0)).ravel()
    ones = np.ones(shape, np.float32)
    if ok.sum() < 2 * _n_terms(len(shape), 1):
        return ones
    y = np.log(num_s.ravel()[ok] / den_s.ravel()[ok])
    w = den_s.ravel()[ok] / den_s.ravel()[ok].mean()
    basis = _poly_basis(centres, shape, max_degree)[ok]         # (cells, terms)
    fold = _checkerboard(num_s.shape)[ok]
    degree = _cv_degree(basis, y, w, fold, len(shape), max_degree)
    if degree == 0:
        return ones
    cols = _n_terms(len(shape), degree)
    coef, rw = _robust_fit(basis[:, :cols], y, w)
    coef[0] -= np.sum((basis[:, :cols] @ coef) * w * rw) / np.sum(w * rw)
    # no extrapolation: beyond the inliers' range (corners of background) the field is
    # held at the range the evidence covers
    seen = basis[:, :cols] @ coef
    log = _poly_basis([np.arange(n) + 0.5 for n in shape], shape, degree) @ coef
    log = np.clip(log, seen.min(), seen.max())
    return np.exp(log).reshape(shape).astype(np.float32)


def _n_terms(ndim: int, degree: int) -> int:
    """Monomials of total degree <= `degree` in `ndim` variables."""
    from math import comb

    return comb(ndim + degree, degree)


def _poly_basis(centres: list[np.ndarray], shape: tuple[int, ...], degree: int
                ) -> np.ndarray:
    """(cells, terms) monomials of the grid of `centres` (per axis, in cells of a grid of
    `shape`), ordered by total degree (the first ``_n_terms(d, k)`` columns are those of
    degree <= k); coordinates centred and scaled by the longest side (isotropic)."""
    from itertools import product

    half = max(shape) / 2
    coords = [(c - n / 2) / half for c, n in zip(centres, shape)]
    grid = [g.ravel() for g in np.meshgrid(*coords, indexing="ij")]
    powers = sorted((p for p in product(range(degree + 1), repeat=len(shape))
                     if sum(p) <= degree), key=lambda p: (sum(p), [-q for q in p]))
    return np.stack([np.prod([g ** q for g, q in zip(grid, p)], axis=0) for p in powers],
                    axis=1)


def _checkerboard(shape: tuple[int, ...]) -> np.ndarray:
    """Fold 0/1 of every cell: a checkerboard of blocks, :data:`CV_BLOCKS` per side."""
    idx = np.meshgrid(*[np.arange(n) * CV_BLOCKS // n for n in shape], indexing="ij")
    return (np.sum(idx, axis=0) % 2).ravel()


def _robust_fit(A: np.ndarray, y: np.ndarray, w: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Huber IRLS: coefficients and the final robust weights (residual scale by MAD)."""
    rw = np.ones_like(y)
    coef = np.zeros(A.shape[1])
    for _ in range(_IRLS):
        sw = np.sqrt(w * rw)
        coef = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)[0]
        r = y - A @ coef
        scale = 1.4826 * np.median(np.abs(r - np.median(r))) + 1e-12
        a = np.abs(r) / (_HUBER * scale)
        rw = np.where(a <= 1, 1.0, 1.0 / np.maximum(a, 1e-12))
    return coef, rw


def _cv_degree(basis, y, w, fold, ndim: int, max_degree: int) -> int:
    """Degree whose fit on one fold best predicts the other (weighted Huber loss, both
    ways), among those that beat the flat field by :data:`EVIDENCE` standard errors of
    the paired per-cell loss differences (a one-sided z-test; 0 when none does)."""
    losses: list[np.ndarray] = []
    for degree in range(max_degree + 1):
        cols = _n_terms(ndim, degree)
        loss = np.empty_like(y)
        for f in (0, 1):
            train, test = fold == f, fold != f
            if train.sum() <= cols or not test.any():
                return _best(losses)
            coef, _ = _robust_fit(basis[train, :cols], y[train], w[train])
            r = y[test] - basis[test, :cols] @ coef
            # residuals of the flat model set the Huber scale, the same for every degree
            r0 = y[test] - np.average(y[test], weights=w[test])
            scale = 1.4826 * np.median(np.abs(r0 - np.median(r0))) + 1e-12
            a = np.abs(r) / (_HUBER * scale)
            loss[test] = w[test] * np.where(a <= 1, a * a, 2 * a - 1)
        losses.append(loss)
    return _best(losses)


def _best(losses: list[np.ndarray]) -> int:
    """:func:`_cv_degree`'s choice from the per-cell held-out losses of degrees 0, 1..."""
    best, best_total = 0, float(losses[0].sum()) if losses else 0.0
    for degree, loss in enumerate(losses[1:], 1):
        gain = losses[0] - loss
        se = np.sqrt(gain.size) * gain.std()
        if gain.sum() > EVIDENCE * se and loss.sum() < best_total:
            best, best_total = degree, float(loss.sum())
    return best


def upsample_linear_at(small: np.ndarray, shape: tuple[int, ...], region) -> np.ndarray:
    """``upsample_linear(small, shape)[np.ix_(*region)]`` without the full-size array.

    Parameters
    ----------
    small : ndarray
        The coarse grid.
    shape : tuple of int
        Shape of the whole upsampled array.
    region : sequence of 1-D int arrays
        Output indices per axis (a block: ``arange(start, stop)``; a strided copy:
        ``arange(0, n, step)``).

    Returns
    -------
    ndarray of float32
        Separable linear weights in float64, the same grid-mode coordinates and held
        edges as :func:`upsample_linear` (which is this over the whole grid).
    """
    small = np.asarray(small, np.float64)
    weights = []
    for m, n, idx in zip(small.shape, shape, region):
        x = np.clip((np.asarray(idx) + 0.5) * (m / n) - 0.5, 0, m - 1)
        lo = np.floor(x).astype(np.intp)
        weights.append((lo, np.minimum(lo + 1, m - 1), x - lo))
    # the last axes first, while the array is small; the first axis last, in slabs of
    # whole rows (a gather of contiguous rows, and no full-size float64 temporary)
    out = small
    for axis in range(small.ndim - 1, 0, -1):
        lo, hi, w = weights[axis]
        w = w.reshape((-1,) + (1,) * (small.ndim - axis - 1))
        out = np.take(out, lo, axis) * (1 - w) + np.take(out, hi, axis) * w
    lo, hi, w = weights[0]
    result = np.empty((lo.size,) + out.shape[1:], np.float32)
    row = max(1, int(np.prod(out.shape[1:])))
    step = max(1, _SLAB // row)
    w = w.reshape((-1,) + (1,) * (small.ndim - 1))
    for i in range(0, lo.size, step):
        sl = slice(i, i + step)
        result[sl] = out[lo[sl]] * (1 - w[sl]) + out[hi[sl]] * w[sl]
    return result


def inlier_class_means(crops, label_crop, class_means: dict[int, float]) -> dict[int, float]:
    """The class means the field divides by: of the box pixels that :func:`field_terms`
    counts as inliers of each label, `label_crop(crop)` labelling each crop as the image
    will be labelled.

    The boxes' plain means are not what the labelled inliers average: the labels and the
    inlier gate truncate each class's noise differently, and the field then follows where
    each class lies (measured: class ratios 1.02..1.07 after correction, a field error
    near the field itself). A class with no inlier keeps its mean.
    """
    sums = {k: [0.0, 0] for k in class_means}
    for crop in crops:
        for k, (total, count) in inlier_sums(crop, label_crop(crop), class_means).items():
            sums[k][0] += total
            sums[k][1] += count
    return {k: (t / n if n else class_means[k]) for k, (t, n) in sums.items()}
