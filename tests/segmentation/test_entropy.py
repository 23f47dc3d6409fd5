"""Tile entropy against a brute force built tile by tile from the Haar matrix."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from napari_swa_imesh.segmentation._entropy import entropy_feature_names, tile_entropy


def _haar_matrix(ndim: int) -> np.ndarray:
    h2 = np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2.0)
    return functools.reduce(np.kron, [h2] * ndim)


def _entropy(values: np.ndarray) -> float:
    total = 0.0
    for y in values.ravel():
        if y != 0:
            total -= abs(y) * math.log(abs(y))
    return total / values.size


def _brute_tile_features(tile: np.ndarray, scale: int) -> list[float]:
    """Pyramid of one tile, level by level, each 2**d block times the Haar matrix."""
    ndim = tile.ndim
    matrix = _haar_matrix(ndim)
    approx = tile.astype(np.float64)
    per_level = []
    for _ in range(scale):
        coarse = tuple(side // 2 for side in approx.shape)
        bands = np.empty((2**ndim,) + coarse)
        for index in np.ndindex(coarse):
            block = approx[tuple(slice(2 * i, 2 * i + 2) for i in index)]
            bands[(slice(None),) + index] = matrix @ block.ravel()
        approx = bands[0]
        per_level.append([_entropy(bands[n]) for n in range(1, 2**ndim)])
    return [_entropy(approx)] + [h for level in per_level for h in level]


def _brute_force(image: np.ndarray, scale: int) -> np.ndarray:
    block = 2**scale
    padded = np.pad(image.astype(np.float64),
                    [(0, (-s) % block) for s in image.shape], mode="symmetric")
    grid = tuple(s // block for s in padded.shape)
    out = np.empty(grid + ((2**image.ndim - 1) * scale + 1,))
    for index in np.ndindex(grid):
        tile = padded[tuple(slice(i * block, (i + 1) * block) for i in index)]
        out[index] = _brute_tile_features(tile, scale)
    return out


CASES = [((13, 22), 0), ((13, 22), 1), ((13, 22), 3), ((16, 8), 2),
         ((9, 6, 11), 1), ((9, 6, 11), 2), ((4, 5, 3, 6), 1)]


@pytest.mark.parametrize("shape, scale", CASES, ids=str)
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32, np.float64],
                         ids=lambda d: np.dtype(d).name)
def test_matches_brute_force(shape, scale, dtype):
    rng = np.random.default_rng(sum(shape) + scale)
    image = (rng.random(shape) * 6 - (0 if dtype == np.uint8 else 3)).astype(dtype)
    features = tile_entropy(image, scale)
    expected_shape = tuple(math.ceil(s / 2**scale) for s in shape)
    assert features.shape == expected_shape + ((2 ** len(shape) - 1) * scale + 1,)
    assert features.dtype == np.float64
    np.testing.assert_allclose(features, _brute_force(image, scale), rtol=1e-10, atol=1e-12)


def test_mask_fills_with_the_tile_valid_mean():
    rng = np.random.default_rng(5)
    image = rng.normal(size=(12, 10)) + 2
    mask = rng.random(image.shape) < 0.7
    mask[:4, :4] = False  # one scale-2 tile without any valid pixel
    features = tile_entropy(image, 2, mask=mask)
    # brute force: fill per tile on the mirror-padded image, then transform
    padded = np.pad(image, [(0, 0), (0, 2)], mode="symmetric")
    valid = np.pad(mask, [(0, 0), (0, 2)], mode="symmetric")
    filled = padded.copy()
    for i in range(3):
        for j in range(3):
            tile = (slice(4 * i, 4 * i + 4), slice(4 * j, 4 * j + 4))
            if valid[tile].any():
                filled[tile] = np.where(valid[tile], padded[tile], padded[tile][valid[tile]].mean())
    expected = _brute_force(filled, 2)
    assert np.isnan(features[0, 0]).all()
    np.testing.assert_allclose(features.reshape(9, -1)[1:], expected.reshape(9, -1)[1:], rtol=1e-10)
    # masked pixels do not matter at all
    scrambled = np.where(mask, image, rng.normal(size=image.shape) * 100)
    np.testing.assert_array_equal(tile_entropy(scrambled, 2, mask=mask), features)


def test_constant_tile_has_zero_detail_entropy():
    image = np.full((8, 8, 8), np.e, dtype=np.float64)
    features = tile_entropy(image, 2)
    np.testing.assert_allclose(features[..., 1:], 0.0, atol=1e-15)
    level_2_approx = np.e * 8.0  # sum over 64 voxels / 2**(3 * 2 / 2)
    np.testing.assert_allclose(features[..., 0], -level_2_approx * np.log(level_2_approx))


def test_full_tiles_do_not_depend_on_padding():
    rng = np.random.default_rng(9)
    image = rng.normal(size=(16, 19))
    np.testing.assert_array_equal(tile_entropy(image, 3)[:, :2], tile_entropy(image[:, :16], 3))


def test_names():
    assert entropy_feature_names(2, 0) == ["entropy_L0"]
    names = entropy_feature_names(3, 2)
    assert len(names) == 7 * 2 + 1
    assert names[:2] == ["entropy_L2", "entropy_D1_1"] and names[-1] == "entropy_D2_7"
    with pytest.raises(ValueError, match="ndim >= 1 and scale >= 0"):
        entropy_feature_names(2, -1)


def test_input_not_mutated_and_bad_inputs():
    image = np.arange(35, dtype=np.int16).reshape(5, 7)
    mask = image % 3 > 0
    before = image.copy()
    tile_entropy(image, 2, mask=mask)
    np.testing.assert_array_equal(image, before)
    with pytest.raises(ValueError, match=r"scale must be an int in 0\.\.2"):
        tile_entropy(image, 3)
    with pytest.raises(ValueError, match="mask must have the image's shape"):
        tile_entropy(image, 1, mask=mask.T)
