"""Tile moments against brute force (numpy/scipy.stats on explicit tiles)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from napari_swa_imesh.segmentation._moments import moment_pyramid, tile_moments

SHAPES = [(13, 22), (16, 16), (9, 6, 11), (5, 6, 3, 7)]
DTYPES = [np.uint8, np.int16, np.float32, np.float64]


def _reference(values: np.ndarray) -> np.ndarray:
    """Population mean, variance, skewness, Pearson kurtosis; (0, 3) convention if constant."""
    values = values.astype(np.float64)
    if values.size == 0:
        return np.full(4, np.nan)
    if np.ptp(values) == 0:
        return np.array([values[0], 0.0, 0.0, 3.0])
    return np.array([
        np.mean(values),
        np.var(values),
        stats.skew(values, bias=True),
        stats.kurtosis(values, fisher=False, bias=True),
    ])


def _tiles(shape, scale):
    block = 2**scale
    grid = tuple(math.ceil(side / block) for side in shape)
    for index in np.ndindex(grid):
        yield index, tuple(slice(i * block, (i + 1) * block) for i in index)


def _assert_matches_brute_force(image, moments, counts, scale, mask=None, rtol=1e-9):
    expected_grid = tuple(math.ceil(side / 2**scale) for side in image.shape)
    assert moments.shape == expected_grid + (4,)
    assert counts.shape == expected_grid
    assert moments.dtype == np.float64 and counts.dtype == np.int64
    if scale == 0:  # one pixel per tile: checked whole-array, the loop would be slow
        valid = np.ones(image.shape, bool) if mask is None else mask
        np.testing.assert_array_equal(counts, valid.astype(np.int64))
        np.testing.assert_array_equal(moments[valid], np.stack(
            [image[valid], 0 * image[valid], 0 * image[valid], 3 + 0 * image[valid]], axis=-1))
        assert np.isnan(moments[~valid]).all()
        return
    for index, tile in _tiles(image.shape, scale):
        values = image[tile] if mask is None else image[tile][mask[tile]]
        values = values.ravel()
        assert counts[index] == values.size
        ref = _reference(values)
        got = moments[index]
        if values.size == 0:
            assert np.isnan(got).all()
            continue
        scale_of_data = max(np.abs(values.astype(float)).max(), 1.0)
        np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=rtol * scale_of_data)
        np.testing.assert_allclose(got[1], ref[1], rtol=rtol, atol=rtol * 1e-6 * scale_of_data**2)
        np.testing.assert_allclose(got[2:], ref[2:], rtol=0, atol=rtol)


def _random_image(shape, dtype, rng):
    if np.dtype(dtype).kind in "iu":
        info = np.iinfo(dtype)
        # a narrow range makes constant and two-valued tiles common at small scales
        high = 4 if dtype == np.uint8 else info.max
        low = 0 if dtype == np.uint8 else info.min
        return rng.integers(low, high, size=shape, endpoint=True).astype(dtype)
    return (rng.standard_gamma(2.0, size=shape) * 50 - 20).astype(dtype)


@pytest.mark.parametrize("shape", SHAPES, ids=str)
@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: np.dtype(d).name)
def test_pyramid_matches_brute_force(shape, dtype):
    rng = np.random.default_rng(sum(shape) + np.dtype(dtype).itemsize)
    image = _random_image(shape, dtype, rng)
    max_scale = int(max(shape)).bit_length() - 1
    pyramid = moment_pyramid(image, max_scale=max_scale)
    assert len(pyramid) == max_scale + 1
    for scale, (moments, counts) in enumerate(pyramid):
        _assert_matches_brute_force(image, moments, counts, scale)


@pytest.mark.parametrize("shape", SHAPES, ids=str)
def test_mask_excludes_pixels(shape):
    rng = np.random.default_rng(len(shape))
    image = rng.normal(size=shape) * 3 + 10
    mask = rng.random(shape) < 0.6
    mask[: min(4, shape[0])] = False  # whole tiles without valid pixels at small scales
    max_scale = int(max(shape)).bit_length() - 1
    pyramid = moment_pyramid(image, max_scale=max_scale, mask=mask)
    assert np.isnan(pyramid[1][0][0]).all() and (pyramid[1][1][0] == 0).all()
    for scale, (moments, counts) in enumerate(pyramid):
        _assert_matches_brute_force(image, moments, counts, scale, mask=mask)


def test_constant_tiles_follow_the_convention():
    image = np.zeros((8, 12))
    image[:4, :4] = 7.25  # constant at scale 2
    image[:4, 4:8] = [0.1, 0.2, 0.3, 0.4]  # varies along columns
    image[4:, :] = 1e4 + 0.1  # constant with an offset whose mean is not exact in binary
    moments, counts = tile_moments(image, 2)
    np.testing.assert_array_equal(moments[0, 0], [7.25, 0.0, 0.0, 3.0])
    np.testing.assert_array_equal(moments[1, :, 2:], [[0.0, 3.0]] * 3)
    np.testing.assert_allclose(moments[1, :, 1], 0.0, atol=1e-20)
    assert moments[0, 1, 3] == pytest.approx(1.64)  # uniform on 4 points: kurtosis 1.64
    np.testing.assert_array_equal(counts, 16)


@pytest.mark.parametrize("offset, spread", [(1e4, 1.0), (1e4, 1e-3), (3e4, 20.0)])
def test_large_offset_is_exact(offset, spread):
    """Data that defeats raw power sums: checked against extended precision."""
    if np.finfo(np.longdouble).eps > 1e-18:
        pytest.skip("needs 80-bit long double for the reference")
    rng = np.random.default_rng(42)
    image = offset + spread * rng.standard_gamma(3.0, size=(24, 40))
    if spread >= 1:
        image = np.round(image).astype(np.uint16)  # CT-like integers
    moments, _ = tile_moments(image, 3)
    worst_naive = 0.0
    for index, tile in _tiles(image.shape, 3):
        values = image[tile].ravel().astype(np.longdouble)
        dev = values - values.mean()
        var = np.mean(dev**2)
        ref = np.array([values.mean(), var, np.mean(dev**3) / var**1.5,
                        np.mean(dev**4) / var**2], dtype=np.float64)
        np.testing.assert_allclose(moments[index][0], ref[0], rtol=1e-14)
        np.testing.assert_allclose(moments[index][1], ref[1], rtol=1e-9)
        np.testing.assert_allclose(moments[index][2:], ref[2:], rtol=0, atol=1e-9)
        # guard: the same tile through float64 raw power sums is far off
        x = image[tile].ravel().astype(np.float64)
        s1, s2, s3, s4 = (np.mean(x**p) for p in (1, 2, 3, 4))
        naive_var = s2 - s1**2
        naive_m4 = s4 - 4 * s1 * s3 + 6 * s1**2 * s2 - 3 * s1**4
        worst_naive = max(worst_naive, abs(naive_m4 / naive_var**2 - ref[3]))
    assert worst_naive > 1e-3


@pytest.mark.parametrize("shape", [(13, 22), (9, 6, 11)], ids=str)
def test_tile_moments_is_the_pyramid_entry(shape):
    rng = np.random.default_rng(7)
    image = rng.normal(size=shape)
    mask = rng.random(shape) < 0.8
    pyramid = moment_pyramid(image, max_scale=3, mask=mask)
    for scale in range(4):
        moments, counts = tile_moments(image, scale, mask=mask)
        np.testing.assert_array_equal(moments, pyramid[scale][0])
        np.testing.assert_array_equal(counts, pyramid[scale][1])


def test_full_tiles_count_and_grid():
    image = np.ones((20, 9, 33), dtype=np.float32)
    for scale, (moments, counts) in enumerate(moment_pyramid(image, max_scale=5)):
        block = 2**scale
        assert counts.shape == (math.ceil(20 / block), math.ceil(9 / block), math.ceil(33 / block))
        assert counts.sum() == image.size
        assert counts[0, 0, 0] == min(block, 20) * min(block, 9) * min(block, 33)
        np.testing.assert_array_equal(moments[..., 0], 1.0)


def test_input_not_mutated():
    rng = np.random.default_rng(3)
    image = rng.integers(0, 1000, size=(9, 14), dtype=np.int16)
    mask = rng.random((9, 14)) < 0.5
    before, mask_before = image.copy(), mask.copy()
    moment_pyramid(image, max_scale=3, mask=mask)
    tile_moments(image, 2, mask=mask)
    np.testing.assert_array_equal(image, before)
    np.testing.assert_array_equal(mask, mask_before)


def test_bad_inputs():
    image = np.zeros((12, 20))
    with pytest.raises(ValueError, match=r"max_scale must be an int in 0\.\.4"):
        moment_pyramid(image, max_scale=5)
    with pytest.raises(ValueError, match=r"scale must be an int in 0\.\.4"):
        tile_moments(image, -1)
    with pytest.raises(ValueError, match="scale must be an int"):
        tile_moments(image, 2.0)
    with pytest.raises(ValueError, match=r"mask must have the image's shape \(12, 20\)"):
        tile_moments(image, 1, mask=np.ones((12, 21), dtype=bool))
    with pytest.raises(TypeError, match="mask must be a boolean"):
        tile_moments(image, 1, mask=np.ones((12, 20)))
    with pytest.raises(ValueError, match="NaN or infinite"):
        tile_moments(np.full((4, 4), np.nan), 1)
