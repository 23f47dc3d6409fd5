"""Correlation lengths: ACF against an explicit loop over lags, fit against known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

from napari_swa_imesh.segmentation._correlation import (
    _fit_exponential,
    _tile_autocorrelation,
    tile_correlation_lengths,
)


def _brute_acf(tile: np.ndarray, valid: np.ndarray, axis: int, max_lag: int) -> np.ndarray:
    """Pooled unbiased ACF of one tile along `axis`, explicit loops over lags and lines."""
    mean = tile[valid].mean()
    moved = np.moveaxis(tile, axis, -1).reshape(-1, tile.shape[axis])
    ok = np.moveaxis(valid, axis, -1).reshape(moved.shape)
    acf = []
    for lag in range(max_lag + 1):
        total, pairs = 0.0, 0
        for line, line_ok in zip(moved, ok):
            for i in range(line.size - lag):
                if line_ok[i] and line_ok[i + lag]:
                    total += (line[i] - mean) * (line[i + lag] - mean)
                    pairs += 1
        acf.append(total / pairs if pairs else np.nan)
    return np.array(acf) / acf[0]


@pytest.mark.parametrize("shape, scale",
                         [((13, 22), 2), ((16, 16), 3), ((9, 7, 12), 2), ((5, 4, 6, 7), 2)],
                         ids=str)
@pytest.mark.parametrize("with_mask", [False, True])
def test_acf_matches_explicit_loop(shape, scale, with_mask):
    rng = np.random.default_rng(len(shape) * 10 + scale)
    image = rng.normal(size=shape).cumsum(axis=-1) + 50  # correlated, offset
    mask = rng.random(shape) < 0.75 if with_mask else np.ones(shape, dtype=bool)
    rho, usable, flat, counts = _tile_autocorrelation(
        image, mask if with_mask else None, scale)
    block, max_lag = 2**scale, 2**scale // 2
    assert rho.shape == tuple(math.ceil(s / block) for s in shape) + (len(shape), max_lag + 1)
    grid = counts.shape
    checked = 0
    for index in [(0,) * len(shape), tuple(g - 1 for g in grid), tuple(g // 2 for g in grid)]:
        window = tuple(slice(i * block, (i + 1) * block) for i in index)
        tile, valid = image[window], mask[window]
        assert counts[index] == valid.sum()
        for axis in range(len(shape)):
            expected = _brute_acf(tile, valid, axis, max_lag)
            ok = usable[index][axis]
            np.testing.assert_array_equal(ok, np.isfinite(expected))
            np.testing.assert_allclose(rho[index][axis][ok], expected[ok], rtol=1e-9, atol=1e-11)
            checked += ok.sum()
    assert checked > 0


@pytest.mark.parametrize("length", [0.3, 1.0, 2.5, 6.0, 15.9])
def test_fit_recovers_exact_exponential(length):
    lags = np.arange(9.0)
    rho = np.exp(-lags / length)[np.newaxis]
    fitted = _fit_exponential(rho, np.ones(rho.shape, dtype=bool), 16)
    np.testing.assert_allclose(fitted, [length], rtol=1e-8)


def test_fit_is_the_least_squares_optimum_on_noisy_acfs():
    rng = np.random.default_rng(11)
    lags = np.arange(5.0)
    true = rng.uniform(0.2, 8.0, size=200)
    rho = np.exp(-lags / true[:, np.newaxis]) + rng.normal(scale=0.15, size=(200, 5))
    rho[:, 0] = 1.0
    fitted = _fit_exponential(rho, np.ones(rho.shape, dtype=bool), 8)
    for row, length in zip(rho, fitted):
        def sse(rate, row=row):
            return np.sum((row[1:] - np.exp(-lags[1:] * rate)) ** 2)
        best = minimize_scalar(sse, bounds=(1 / 8, 20), method="bounded",
                               options={"xatol": 1e-12})
        assert sse(1 / length) <= best.fun + 1e-10


def _exponential_field(shape, lengths, rng, burn_in=64):
    """Separable AR(1) field: correlation exp(-|h_a| / lengths[a]) along each axis."""
    field = rng.normal(size=tuple(s + burn_in for s in shape))
    for axis, length in enumerate(lengths):
        phi = math.exp(-1.0 / length)
        field = lfilter([math.sqrt(1 - phi**2)], [1.0, -phi], field, axis=axis)
    return field[tuple(slice(burn_in, None) for _ in shape)]


@pytest.mark.parametrize("shape, lengths, scale", [
    ((128, 256), (1.0, 3.0), 5),
    ((32, 64, 64), (1.0, 2.0, 4.0), 4),
], ids=["2d", "3d"])
def test_recovers_correlation_length_of_ar1_fields(shape, lengths, scale):
    rng = np.random.default_rng(2024)
    field = _exponential_field(shape, lengths, rng)
    fitted = tile_correlation_lengths(field, scale)
    assert fitted.shape == tuple(s // 2**scale for s in shape) + (len(shape),)
    median = np.median(fitted.reshape(-1, len(shape)), axis=0)
    np.testing.assert_allclose(median, lengths, rtol=0.12)


def test_conventions_constant_masked_thin_and_clipped():
    rng = np.random.default_rng(4)
    image = rng.normal(size=(16, 17))
    image[:8, :8] = 3.5  # constant tile
    image[:, 8:16] = np.linspace(0, 1, 16)[:, np.newaxis]  # constant along axis 1
    mask = np.ones(image.shape, dtype=bool)
    mask[8:, :8] = False  # tile without valid pixels
    lengths = tile_correlation_lengths(image, 3, mask=mask)
    assert lengths.shape == (2, 3, 2)
    np.testing.assert_array_equal(lengths[0, 0], [0.0, 0.0])
    assert np.isnan(lengths[1, 0]).all()
    # column 16 is one pixel wide: no pair along axis 1, pairs along axis 0
    assert np.isnan(lengths[:, 2, 1]).all() and np.isfinite(lengths[:, 2, 0]).all()
    # ramp along axis 0, constant along axis 1: decorrelation not reached -> clipped to 8
    np.testing.assert_array_equal(lengths[:, 1, 1], 8.0)
    assert ((lengths[:, 1, 0] > 0.05) & (lengths[:, 1, 0] <= 8)).all()


def test_input_not_mutated_and_bad_inputs():
    image = np.arange(64, dtype=np.uint8).reshape(8, 8)
    before = image.copy()
    tile_correlation_lengths(image, 2, mask=image > 3)
    np.testing.assert_array_equal(image, before)
    with pytest.raises(ValueError, match="needs scale >= 2"):
        tile_correlation_lengths(image, 1)
    with pytest.raises(ValueError, match=r"scale must be an int in 0\.\.3"):
        tile_correlation_lengths(image, 4)
