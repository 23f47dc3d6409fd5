"""Haar pyramid: brute force against the Kronecker Haar matrix, perfect reconstruction."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from napari_swa_imesh.segmentation._haar import haar_analysis, haar_synthesis

SHAPES = {2: (8, 16), 3: (4, 8, 12), 4: (4, 4, 8, 4)}


def _haar_matrix(ndim: int) -> np.ndarray:
    """H_2 (x) ... (x) H_2, d times: acts on a C-order flattened 2 x ... x 2 block."""
    h2 = np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2.0)
    return functools.reduce(np.kron, [h2] * ndim)


def _brute_one_level(image: np.ndarray) -> np.ndarray:
    """All 2**d bands of one level, block by block with the Haar matrix."""
    ndim = image.ndim
    matrix = _haar_matrix(ndim)
    coarse = tuple(side // 2 for side in image.shape)
    out = np.empty((2**ndim,) + coarse)
    for index in np.ndindex(coarse):
        block = image[tuple(slice(2 * i, 2 * i + 2) for i in index)]
        out[(slice(None),) + index] = matrix @ block.ravel()
    return out


@pytest.mark.parametrize("ndim", [2, 3, 4])
def test_matches_haar_matrix_per_block(ndim):
    rng = np.random.default_rng(ndim)
    image = rng.normal(size=SHAPES[ndim])
    approx, details = haar_analysis(image, 2)
    level1 = _brute_one_level(image)
    np.testing.assert_allclose(details[0], level1[1:], rtol=0, atol=1e-12)
    level2 = _brute_one_level(level1[0])
    np.testing.assert_allclose(details[1], level2[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(approx, level2[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("ndim", [2, 3, 4])
@pytest.mark.parametrize("levels", [0, 1, 2])
def test_perfect_reconstruction_and_energy(ndim, levels):
    rng = np.random.default_rng(10 * ndim + levels)
    image = rng.normal(size=SHAPES[ndim]) * 100 + 7
    approx, details = haar_analysis(image, levels)
    assert len(details) == levels
    for k, level in enumerate(details, start=1):
        assert level.shape == (2**ndim - 1,) + tuple(s // 2**k for s in image.shape)
        assert level.dtype == np.float64
    np.testing.assert_allclose(haar_synthesis(approx, details), image, rtol=0, atol=1e-10)
    energy = np.sum(approx**2) + sum(np.sum(level**2) for level in details)
    np.testing.assert_allclose(energy, np.sum(image**2), rtol=1e-12)


@pytest.mark.parametrize("ndim", [2, 3, 4])
def test_band_index_is_binary_code_of_high_pass_axes(ndim):
    shape = SHAPES[ndim]
    for axis in range(ndim):
        # alternating +-1 along `axis` only: pure high-pass along that axis
        grid = np.indices(shape)[axis]
        image = (-1.0) ** grid
        _, details = haar_analysis(image, 1)
        expected_band = 2 ** (ndim - 1 - axis)
        energy = np.sum(details[0] ** 2, axis=tuple(range(1, ndim + 1)))
        assert np.argmax(energy) == expected_band - 1
        np.testing.assert_allclose(energy.sum(), image.size, rtol=1e-12)


def test_worked_example_2d():
    approx, details = haar_analysis(np.array([[1, 3], [5, 7]], dtype=np.uint8), 1)
    np.testing.assert_allclose(approx, [[8.0]])
    # (-2) high-pass along columns, (-4) along rows, 0 diagonal
    np.testing.assert_allclose(details[0][:, 0, 0], [-2.0, -4.0, 0.0])


def test_constant_image_has_no_detail():
    approx, details = haar_analysis(np.full((8, 8, 8), 3, dtype=np.int16), 3)
    np.testing.assert_allclose(approx, [[[3.0 * 8**1.5]]])
    assert all(np.all(level == 0) for level in details)


def test_input_not_mutated():
    image = np.arange(64, dtype=np.float32).reshape(8, 8)
    before = image.copy()
    approx, details = haar_analysis(image, 3)
    haar_synthesis(approx, details)
    np.testing.assert_array_equal(image, before)


def test_bad_inputs():
    with pytest.raises(ValueError, match=r"multiple of 2\*\*2 = 4; got shape \(8, 6\)"):
        haar_analysis(np.zeros((8, 6)), 2)
    with pytest.raises(ValueError, match="levels must be >= 0"):
        haar_analysis(np.zeros((8, 8)), -1)
    with pytest.raises(TypeError, match="levels must be an int"):
        haar_analysis(np.zeros((8, 8)), 1.0)
    with pytest.raises(TypeError, match="real numbers"):
        haar_analysis(np.zeros((4, 4), dtype=complex), 1)
    approx, details = haar_analysis(np.zeros((8, 8)), 2)
    with pytest.raises(ValueError, match=r"details\[0\] must have shape \(3, 4, 4\)"):
        haar_synthesis(approx, [details[1], details[1]])
