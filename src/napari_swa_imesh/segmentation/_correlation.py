"""Correlation lengths per tile and axis (reference eq. 2.23).

For every tile and axis ``a`` the directional autocorrelation is estimated from
the tile's own pixels and fitted with ``exp(-h / lambda_a)``.

Estimator
---------
- ``y = w * (x - mean)``: the mean of the tile's valid pixels is removed, and
  ``w`` is 1 on valid pixels, 0 on masked-out pixels and on padding.
- ``C(h) = sum y(p) y(p + h e_a) / N_p(h)``, the sums running over every line of
  the tile along ``a`` (lines pooled), ``N_p(h) = sum w(p) w(p + h e_a)`` the
  number of valid pairs at lag ``h``: the unbiased estimate, equal to the mean
  of the per-line estimates when every pixel is valid. Both sums are computed by
  FFT along the line, zero-padded to twice the tile size so that nothing wraps
  around.
- ``rho(h) = C(h) / C(0)`` (1 at lag 0).

Fit
---
Least squares of ``exp(-h / lambda)`` to ``rho`` over lags ``1 .. 2**scale / 2``
(lag 0 fits exactly), vectorised over all tiles: starting from the best of a
log-spaced grid of rates (noisy ACFs can have several local minima), a few
Newton steps with backtracking on the rate ``theta = 1 / lambda``, kept in
``[1 / 2**scale, 20]``; so ``lambda`` lies in ``[0.05, 2**scale]`` (0.05: no
correlation measurable at lag 1; ``2**scale``: correlated across the tile).

Conventions: a tile with numerically zero variance (as in :mod:`._moments`) gets
``lambda = 0``; a tile, or an axis of a tile, without any valid pair at lags
``1 .. 2**scale / 2`` (no valid pixel, or a partial edge tile one pixel thick
along that axis) gets NaN.
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft

from napari_swa_imesh._validation import as_image

from ._moments import ZERO_STD_RTOL
from ._tiles import block_spread, block_sum, block_view, tile_means, validate_mask, validate_scale

__all__ = ["tile_correlation_lengths"]

_MAX_RATE = 20.0  # exp(-20) ~ 2e-9: faster decay is indistinguishable from none
_NEWTON_STEPS = 6
_GRID_POINTS = 32  # neighbouring start rates differ by < 25 %
# Work on slabs of tiles of about this many pixels to bound the FFT buffers.
_CHUNK_PIXELS = 2**18


def _lag_sums(data: np.ndarray, tile: int, axis: int, max_lag: int) -> np.ndarray:
    """Sum of data(p) * data(p + h e_axis) within each tile, for h = 0..max_lag.

    `data` has sides multiple of `tile`; returns shape (t_0, ..., t_{d-1}, max_lag + 1).
    """
    ndim = data.ndim
    view = block_view(data, tile)  # (t_0, s, t_1, s, ...)
    line_axis = 2 * axis + 1
    # Zero padding to s + max_lag keeps lags 0..max_lag free of circular wrap-around.
    length = sfft.next_fast_len(tile + max_lag, real=True)
    spectrum = sfft.rfft(view, n=length, axis=line_axis)
    power = spectrum.real**2
    power += spectrum.imag**2
    del spectrum
    # The inverse FFT is linear: sum the power over the tile's lines first, then
    # invert once per tile instead of once per line.
    other_lines = tuple(2 * b + 1 for b in range(ndim) if b != axis)
    power = power.sum(axis=other_lines)  # (t_0, .., t_axis, frequency, t_axis+1, ..)
    frequency_axis = axis + 1
    lagged = sfft.irfft(power, n=length, axis=frequency_axis)
    lagged = lagged[(slice(None),) * frequency_axis + (slice(0, max_lag + 1),)]
    return np.moveaxis(lagged, frequency_axis, -1)


def _fit_exponential(rho: np.ndarray, usable: np.ndarray, tile: int) -> np.ndarray:
    """Least-squares lambda of exp(-h / lambda) to rho(h), h = 0..L, vectorised.

    Parameters
    ----------
    rho : (..., L + 1) ndarray of float64
        Normalised autocorrelation, rho[..., 0] == 1 (lag 0 fits exactly and is
        not used).
    usable : (..., L + 1) ndarray of bool
        Lags that have at least one pair.
    tile : int
        Upper bound of lambda.

    Returns
    -------
    (...) ndarray of float64
        lambda in [1 / _MAX_RATE, tile]; NaN where no lag >= 1 is usable.
    """
    batch = rho.shape[:-1]
    rho = rho[..., 1:].reshape(-1, rho.shape[-1] - 1)  # (M, L): lags 1..L
    usable = usable[..., 1:].reshape(rho.shape)
    rho = np.where(usable, rho, 0.0)
    weight = usable.astype(np.float64)
    lags = np.arange(1.0, rho.shape[-1] + 1.0)
    # Start: the best of a log-spaced grid of rates (the sum of squares can have
    # several local minima when rho is noisy), then Newton from there.
    low = 1.0 / tile
    grid = np.geomspace(low, _MAX_RATE, _GRID_POINTS)
    basis = np.exp(np.multiply.outer(-grid, lags))  # (G, L)
    # ||rho - basis_g||^2 over usable lags = sum w rho^2 - 2 (w rho) . b_g + w . b_g^2
    grid_sse = -2.0 * (weight * rho) @ basis.T + weight @ (basis * basis).T  # (M, G)
    rate = grid[np.argmin(grid_sse, axis=-1)]

    def sse(theta: np.ndarray) -> np.ndarray:
        residual = rho - np.exp(np.multiply.outer(-theta, lags))
        residual *= residual
        return np.einsum("ml,ml->m", residual, weight)

    current = sse(rate)
    for _ in range(_NEWTON_STEPS):
        model = np.exp(np.multiply.outer(-rate, lags))
        residual = rho - model
        jacobian = model * (-lags) * weight  # d model / d theta, 0 on unusable lags
        gradient = np.einsum("ml,ml->m", jacobian, residual)
        gauss_newton = np.einsum("ml,ml->m", jacobian, jacobian)
        # exact second derivative of the sum of squares (d2 model / d theta2 = h^2 model);
        # where it is not positive the Gauss-Newton curvature is used instead
        curvature = gauss_newton - np.einsum("ml,ml->m", residual * weight, model * lags * lags)
        curvature = np.where(curvature > 0, curvature, gauss_newton)
        step = gradient / np.where(curvature > 0, curvature, 1.0)
        pending = np.ones(rate.shape, dtype=bool)
        for shrink in (1.0, 0.5, 0.25):
            trial = np.clip(rate + shrink * step, low, _MAX_RATE)
            trial_sse = sse(trial)
            better = pending & (trial_sse < current)
            rate[better] = trial[better]
            current[better] = trial_sse[better]
            pending &= ~better
    length = 1.0 / rate
    length[~usable.any(axis=-1)] = np.nan
    return length.reshape(batch)


def _tile_autocorrelation(x: np.ndarray, valid: np.ndarray | None, scale: int
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Normalised ACF per tile and axis for lags 0..2**scale / 2.

    Returns
    -------
    rho : (t_0, ..., t_{d-1}, d, L + 1) ndarray of float64
        C(h) / C(0); meaningless where `usable` is False or the tile is flat.
    usable : (t_0, ..., t_{d-1}, d, L + 1) ndarray of bool
        Lags with at least one valid pair.
    flat : (t_0, ..., t_{d-1}) ndarray of bool
        Tiles with numerically zero variance.
    counts : (t_0, ..., t_{d-1}) ndarray of int64
        Valid pixels per tile.
    """
    ndim = x.ndim
    tile = 2**scale
    max_lag = tile // 2
    pad = [(0, (-side) % tile) for side in x.shape]
    has_pad = any(after for _, after in pad)
    if valid is None and has_pad:
        valid = np.ones(x.shape, dtype=bool)
    padded = np.pad(x, pad) if has_pad else x
    valid_padded = None if valid is None else np.pad(valid, pad)
    grid = tuple(side // tile for side in padded.shape)
    if valid_padded is None:
        counts = np.full(grid, tile**ndim, dtype=np.int64)
    else:
        counts = block_sum(valid_padded, tile, dtype=np.int64)
    means = tile_means(padded, counts, scale, valid_padded)

    lag_sums = np.empty(grid + (ndim, max_lag + 1))
    pair_counts = np.empty(grid + (ndim, max_lag + 1))
    if valid_padded is None:
        # every pixel valid: (s - h) pairs per line, s**(d-1) lines
        pair_counts[...] = (tile - np.arange(max_lag + 1.0)) * tile ** (ndim - 1)
    rows = max(1, _CHUNK_PIXELS // (tile**ndim * int(np.prod(grid[1:]))))
    for first in range(0, grid[0], rows):
        pixels = slice(first * tile, (first + rows) * tile)
        tiles = slice(first, first + rows)
        centred = padded[pixels].copy()
        block_view(centred, tile)[...] -= block_spread(means[tiles])
        if valid_padded is not None:
            weight = valid_padded[pixels].astype(np.float64)
            centred *= weight
        for axis in range(ndim):
            lag_sums[tiles, ..., axis, :] = _lag_sums(centred, tile, axis, max_lag)
            if valid_padded is not None:
                pair_counts[tiles, ..., axis, :] = np.rint(_lag_sums(weight, tile, axis, max_lag))

    usable = pair_counts > 0
    covariance = lag_sums / np.where(usable, pair_counts, 1.0)
    variance = covariance[..., :1]  # the same for every axis: all valid pixels of the tile
    rho = covariance / np.where(variance > 0, variance, 1.0)
    flat = np.sqrt(np.maximum(variance[..., 0, 0], 0.0)) <= ZERO_STD_RTOL * np.abs(means)
    return rho, usable, flat, counts


def tile_correlation_worker(x: np.ndarray, valid: np.ndarray | None, scale: int) -> np.ndarray:
    """`tile_correlation_lengths` on checked float64 input (not modified)."""
    rho, usable, flat, counts = _tile_autocorrelation(x, valid, scale)
    lengths = _fit_exponential(rho, usable, 2**scale)  # (t..., d)
    has_pairs = usable[..., 1:].any(axis=-1)
    lengths[flat[..., np.newaxis] & has_pairs] = 0.0
    lengths[counts == 0] = np.nan
    return lengths


def tile_correlation_lengths(image, scale: int, *, mask=None) -> np.ndarray:
    """Correlation length per tile and axis, from the tile's autocorrelation.

    Parameters
    ----------
    image : (N_0, ..., N_{d-1}) array_like of real numbers
        Grey-level image, 2-D or more, any real dtype (computed in float64). Not
        modified.
    scale : int
        Tiles of ``2**scale`` pixels per axis; at least 2 (4 pixels per axis, lags
        0..2 for the fit) and at most ``floor(log2(max side))``.
    mask : (N_0, ..., N_{d-1}) array_like of bool, optional
        True where a pixel counts; masked pixels are left out of means and of
        pair counts.

    Returns
    -------
    (t_0, ..., t_{d-1}, d) ndarray of float64
        ``lambda_a`` in pixels for axis ``a`` (``t_a = ceil(N_a / 2**scale)``),
        in ``[0.05, 2**scale]``; 0 for constant tiles; NaN where no valid pair
        exists at lag 1. Partial edge tiles use their real pixels only (the
        padding has no weight), see the module docstring for the estimator.

    Examples
    --------
    >>> stripes = np.tile([0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0], (8, 1))
    >>> float(tile_correlation_lengths(stripes, 3)[0, 0, 0])  # constant columns: clipped to 8
    8.0
    >>> tile_correlation_lengths(np.ones((8, 8)), 3)[0, 0].tolist()  # constant tile
    [0.0, 0.0]
    """
    x = as_image(image)
    valid = validate_mask(mask, x.shape)
    scale = validate_scale(scale, x.shape)
    if scale < 2:
        raise ValueError(
            f"tile_correlation_lengths needs scale >= 2 (tiles of 4 or more pixels per "
            f"axis, so that lags 0..2 can be fitted); got scale={scale}. Use a larger scale "
            "or a feature set without Z (F1, F2, F5)."
        )
    return tile_correlation_worker(x, valid, scale)
