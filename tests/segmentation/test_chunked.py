"""Chunked application of a saved model: the labels of tiny chunks equal the whole image's."""

import tracemalloc

import numpy as np
import pytest

from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import RecommendedModel, Samples, _chunked, samples_from_truth
from napari_swa_imesh.segmentation._chunked import (
    batch_bytes,
    bytes_per_voxel,
    halo,
    parse_memory,
    plan_chunks,
    predict_chunked,
)
from napari_swa_imesh.segmentation._window_features import multiscale_features


def _two_textures(shape, seed=0):
    """Calm and busy noise separated by a wavy boundary (texture, not intensity)."""
    rng = np.random.default_rng(seed)
    grid = np.indices(shape).sum(0)
    busy = np.sin(grid / 9.0) + 0.3 * rng.normal(size=shape) > 0
    return np.where(busy, rng.normal(0.5, 3, shape), rng.normal(0, 1, shape)).astype(
        np.float32)


@pytest.fixture(scope="module")
def model_2d():
    rng = np.random.default_rng(1)
    train = np.concatenate([rng.normal(0, 1, (64, 64)), rng.normal(0.5, 3, (64, 64))], 1)
    samples = Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [64, 64]},
        {"label": 7, "start": [0, 64], "stop": [64, 128]}]})
    return RecommendedModel(max_scale=4, bias_correction=True,
                            pixels_per_material=3000).fit(train, samples)


@pytest.mark.parametrize("levels", [(0, 0), (2, 0), (3, 1), (4, 2)])
@pytest.mark.parametrize("bias", [False, True])
def test_tiny_chunks_equal_the_whole_image_2d(model_2d, levels, bias):
    model = model_2d
    model.scale, model.finest_scale = levels
    model.bias_correction = bias
    image = _two_textures((150, 140))           # the bias grid needs 150 // 32 = 4 px cells
    whole = model.predict(image)
    labels, plan = predict_chunked(model, image, chunks=(24, 20), scheduler="sync")
    assert labels.numblocks[0] >= 3 and plan["halo"] == halo(model)
    out = labels.compute(scheduler="sync")
    np.testing.assert_array_equal(out, whole)
    assert out.dtype == np.uint8


def test_without_the_margin_chunk_borders_show(model_2d, monkeypatch):
    model = model_2d
    model.scale, model.finest_scale, model.bias_correction = 3, 1, False
    image = _two_textures((150, 140))
    monkeypatch.setattr(_chunked, "halo", lambda m: 0)
    labels, _ = predict_chunked(model, image, chunks=(24, 20), scheduler="sync")
    assert (labels.compute(scheduler="sync") != model.predict(image)).sum() > 20


@pytest.mark.parametrize("level", [1, 2, 3])
def test_features_reach_exactly_two_to_the_level(level):
    # one changed pixel changes level-j features up to 2^j px away, and no farther
    rng = np.random.default_rng(0)
    image = rng.normal(size=(41, 41)).astype(np.float32)
    other = image.copy()
    other[20, 20] += 5
    a, _ = multiscale_features(image, level)
    b, _ = multiscale_features(other, level)
    rows, cols = np.nonzero((a != b).any(-1))
    assert max(np.abs(rows - 20).max(), np.abs(cols - 20).max()) == 1 << level


def test_tiny_chunks_equal_the_whole_volume_3d_with_bias():
    image, truth = tissue_phantom((36, 40, 44), noise=0.06, bias=0.4, spacing=(1, 1, 1))
    model = RecommendedModel(bias_correction=True).fit(image, samples_from_truth(truth))
    assert model.bias_correction
    whole = model.predict(image)
    labels, _ = predict_chunked(model, image, chunks=(12, 16, 16), scheduler="sync")
    np.testing.assert_array_equal(labels.compute(scheduler="sync"), whole)


@pytest.mark.parametrize("shape,scale", [((40, 40, 40), 0), ((40, 40, 40), 3),
                                         ((300, 300), 5)])
def test_memory_model_bounds_the_measured_peak(shape, scale):
    # pure noise: every voxel unsure, the MRF's worst case
    rng = np.random.default_rng(2)
    d, n = len(shape), (1 << scale) + 3
    train = np.concatenate([rng.normal(0, 1, (n,) * d), rng.normal(0.1, 1.5, (n,) * d)], -1)
    boxes = [{"label": 1, "start": [0] * d, "stop": [n] * d},
             {"label": 2, "start": [0] * (d - 1) + [n], "stop": [n] * (d - 1) + [2 * n]}]
    model = RecommendedModel(max_scale=scale, bias_correction=False,
                             pixels_per_material=2000).fit(
        train, Samples.from_dict({"boxes": boxes}))
    model.scale, model.finest_scale = scale, 0
    work = model._standardised(rng.normal(0, 1.2, shape).astype(np.float32))
    tracemalloc.start()
    try:
        _chunked._labels_block(work, model)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    bound = bytes_per_voxel(model, d) * work.size + batch_bytes(model, work.size)
    assert 0.5 * bound < peak <= bound


def test_plan_fits_the_budget_and_refuses_when_nothing_fits(model_2d):
    model = model_2d
    model.scale, model.finest_scale, model.bias_correction = 2, 0, False
    shape = (4000, 3000)
    core, workers = plan_chunks(shape, model, 200_000_000)
    h = halo(model)
    padded = np.prod([c + 2 * h for c in core])
    assert padded * bytes_per_voxel(model, 2) + batch_bytes(model, padded) <= 2e8 / workers
    assert min(core) >= 100
    with pytest.raises(ValueError, match=r"more than the budget of 0\.01 GB; give more memory"):
        plan_chunks(shape, model, 10_000_000)


def test_budget_text():
    assert parse_memory("2GB") == 2_000_000_000 and parse_memory("1GiB") == 1 << 30
    with pytest.raises(ValueError, match="cannot read '2 giga' as an amount of memory"):
        parse_memory("2 giga")
    with pytest.raises(ValueError, match="must be more than 0"):
        parse_memory("0")


def test_nan_unfitted_and_unknown_models_are_refused(model_2d):
    model = model_2d
    model.scale, model.finest_scale, model.bias_correction = 2, 0, False
    image = _two_textures((64, 64))
    image[50, 40] = np.nan
    with pytest.raises(ValueError, match=r"the image has NaN or infinite values; fill"):
        predict_chunked(model, image, chunks=(32, 32), scheduler="sync")
    from napari_swa_imesh.segmentation import SWAModel

    with pytest.raises(ValueError, match="this model is not fitted"):
        predict_chunked(SWAModel(scale=1), image)
    with pytest.raises(TypeError, match="model must be a RecommendedModel or SWAModel"):
        predict_chunked(object(), image)
