"""Feature stacks: shapes, names and values for every set, and the door checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from napari_swa_imesh.segmentation._correlation import tile_correlation_lengths
from napari_swa_imesh.segmentation._entropy import entropy_feature_names, tile_entropy
from napari_swa_imesh.segmentation._features import (
    FEATURE_SETS,
    feature_names,
    feature_stack,
    n_features,
)
from napari_swa_imesh.segmentation._moments import tile_moments


def test_table_2_1():
    assert FEATURE_SETS == {"F1": ("M",), "F2": ("H",), "F3": ("Z",), "F4": ("M", "Z"),
                            "F5": ("H", "M"), "F6": ("H", "Z"), "F7": ("H", "M", "Z")}
    # feature-space sizes of Table 2.1 for 2-D images at scale j
    for j in (2, 3, 5):
        assert [n_features(f"F{i}", 2, j) for i in range(1, 8)] == [
            4, 3 * j + 1, 2, 6, 3 * j + 5, 3 * j + 3, 3 * j + 7]
    assert n_features("f7", 3, 2) == 4 + 7 * 2 + 1 + 3


@pytest.mark.parametrize("shape", [(21, 30), (10, 13, 9), (6, 5, 4, 7)], ids=str)
@pytest.mark.parametrize("feature_set", sorted(FEATURE_SETS))
def test_every_set_matches_its_groups(shape, feature_set):
    rng = np.random.default_rng(len(shape))
    image = (rng.random(shape) * 200).astype(np.uint8)
    mask = rng.random(shape) < 0.8
    scale = 2
    features, counts, names = feature_stack(image, scale, feature_set, mask=mask)
    grid = tuple(math.ceil(s / 2**scale) for s in shape)
    assert features.shape == grid + (n_features(feature_set, len(shape), scale),)
    assert features.dtype == np.float64 and counts.dtype == np.int64
    assert (names == feature_names(feature_set, len(shape), scale)
            and len(names) == features.shape[-1])

    moments, expected_counts = tile_moments(image, scale, mask=mask)
    np.testing.assert_array_equal(counts, expected_counts)
    groups = {
        "M": (moments, ["mean", "variance", "skewness", "kurtosis"]),
        "H": (tile_entropy(image, scale, mask=mask), entropy_feature_names(len(shape), scale)),
        "Z": (tile_correlation_lengths(image, scale, mask=mask),
              [f"corr_length_axis{a}" for a in range(len(shape))]),
    }
    start = 0
    for group in FEATURE_SETS[feature_set]:
        values, group_names = groups[group]
        stop = start + values.shape[-1]
        np.testing.assert_array_equal(features[..., start:stop], values)
        assert names[start:stop] == group_names
        start = stop
    assert start == features.shape[-1]


def test_counts_without_moments_and_case_insensitive_name():
    image = np.random.default_rng(1).normal(size=(9, 14))
    features, counts, names = feature_stack(image, 2, "f2")
    np.testing.assert_array_equal(counts, [[16, 16, 16, 8], [16, 16, 16, 8], [4, 4, 4, 2]])
    assert names[0] == "entropy_L2" and features.shape == (3, 4, 7)


def test_scale_zero_and_input_not_mutated():
    image = np.arange(12, dtype=np.int16).reshape(3, 4)
    mask = image > 2
    before, mask_before = image.copy(), mask.copy()
    features, counts, _ = feature_stack(image, 0, "F5", mask=mask)
    assert features.shape == (3, 4, 5)
    np.testing.assert_array_equal(counts, mask.astype(np.int64))
    np.testing.assert_array_equal(features[mask][:, 1], image[mask])  # the mean column
    feature_stack(image, 2, "F7", mask=mask)
    np.testing.assert_array_equal(image, before)
    np.testing.assert_array_equal(mask, mask_before)


def test_bad_inputs():
    image = np.zeros((16, 20))
    with pytest.raises(ValueError, match=r"unknown feature set 'F8'.*F1 M, F2 H.*F7 H\+M\+Z"):
        feature_stack(image, 2, "F8")
    with pytest.raises(TypeError, match="feature_set must be a string"):
        feature_stack(image, 2, 1)
    with pytest.raises(ValueError, match="feature set F6 contains correlation lengths"):
        feature_stack(image, 1, "f6")
    with pytest.raises(ValueError, match=r"scale must be an int in 0\.\.4"):
        feature_stack(image, 5)
    with pytest.raises(ValueError, match="mask must have the image's shape"):
        feature_stack(image, 2, mask=np.ones((16, 16), dtype=bool))
    with pytest.raises(ValueError, match="must be at least 2-D"):
        feature_stack(np.zeros(16), 2)
