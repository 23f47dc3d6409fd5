"""Blocked cross-validation (folds of half-boxes) and the inlier-only bias field."""

import numpy as np
import pytest

from napari_swa_imesh.segmentation import RecommendedModel, Samples, estimate_bias_field, segment
from napari_swa_imesh.segmentation._bias import field_terms
from napari_swa_imesh.segmentation._blocked_cv import blocked_cv_errors


def _two_boxes(shape=(32, 32)):
    return Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [shape[0], shape[1] // 2]},
        {"label": 2, "start": [0, shape[1] // 2], "stop": list(shape)}]})


def test_blocked_cv_is_chance_for_indistinguishable_materials():
    rng = np.random.default_rng(0)
    img = rng.normal(0, 1, (64, 64)).astype(np.float32)
    err = blocked_cv_errors(img, _two_boxes((64, 64)), 2)
    assert sorted(err) == [0, 1, 2]
    assert all(35 < e < 65 for e in err.values())


def test_blocked_cv_sees_a_drift_the_pixel_cv_misses():
    # material 2 is bright in the top half of its box and dark in the bottom half: random
    # pixels of both halves train and test alike, whole halves do not
    rng = np.random.default_rng(1)
    right = np.where(np.arange(64)[:, None] < 32, 3.0, -3.0) + rng.normal(0, .1, (64, 32))
    img = np.concatenate([rng.normal(0, 1, (64, 32)), right], 1).astype(np.float32)
    model = RecommendedModel(max_scale=0, beta=0, bias_correction=False).fit(
        img, _two_boxes((64, 64)))
    assert model.level_error[0] < 10
    assert model.scores["eps_blocked"] > 30


def test_blocked_cv_refuses_one_pixel_thick_boxes():
    img = np.random.default_rng(2).normal(0, 1, (16, 16)).astype(np.float32)
    s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [1, 1]},
                                     {"label": 2, "start": [4, 4], "stop": [12, 12]}]})
    assert blocked_cv_errors(img, s, 0) is None


def test_blocked_cv_in_scores_summary_and_description():
    rng = np.random.default_rng(3)
    img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(4, 1, (32, 16))], 1)
    result = segment(img, _two_boxes())
    assert 0 <= result.model.scores["eps_blocked"] < 10
    assert result.summary()["eps_blocked"] == result.model.scores["eps_blocked"]
    assert "blocked CV error" in result.describe()


def test_bias_field_ignores_background_no_material_describes():
    # materials 1 and 2 with no bias; a dark background (labelled as the darkest
    # material, as a classifier without a background class does) must not pull the field
    rng = np.random.default_rng(4)
    img = np.where(np.arange(64)[None, :] < 32, 1.0, 2.0) * np.ones((64, 1))
    img[:, :16] = np.abs(rng.normal(0, 0.05, (64, 16)))
    labels = np.where(np.arange(64)[None, :] < 32, 1, 2) * np.ones((64, 64), int)
    field = estimate_bias_field(img.astype(np.float32), labels, {1: 1.0, 2: 2.0})
    assert np.all(np.abs(field - 1) < 0.02)
    num, den = field_terms(img.astype(np.float32), img.astype(np.float32), labels,
                           {1: 1.0, 2: 2.0})
    assert np.all(den[:, :14] == 0) and np.all(den[:, 18:30] == 1)


def test_bias_field_still_found_on_inliers():
    # a smooth 20 % ramp is recovered from pixels whose class is right
    ramp = np.linspace(0.9, 1.1, 64)[:, None] * np.ones((1, 64))
    labels = np.where(np.arange(64)[None, :] < 32, 1, 2) * np.ones((64, 64), int)
    img = (ramp * np.where(labels == 1, 1.0, 2.0)).astype(np.float32)
    field = estimate_bias_field(img, labels, {1: 1.0, 2: 2.0})
    assert np.corrcoef(field[:, 40], ramp[:, 0])[0, 1] > 0.99
    with pytest.raises(ValueError, match="must be"):
        RecommendedModel(bias_correction="maybe")
