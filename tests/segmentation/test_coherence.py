"""Structure-tensor coherence features of the recommended method: what they measure, that
turning, flipping or transposing the image changes no feature and no label, and that they
tell a texture of fibres from one of crossed fibres however the fibres are turned."""

import numpy as np
import pytest
from scipy import ndimage as ndi

from napari_swa_imesh.segmentation import RecommendedModel, Samples, _window_features, dice_scores
from napari_swa_imesh.segmentation._window_features import (
    coherence_pairs,
    multiscale_features,
    squared_coherence,
)

N = 96


def _fibres(rng, shape, axis):
    """Noise smeared along `axis`: detail across it only."""
    return ndi.gaussian_filter1d(rng.normal(0, 1, shape), 4.0, axis=axis)


def _textures(rng):
    """Fibres along x, and crossed fibres with the same energy per level summed over axes
    (so mean, spread and the Haar energies cannot tell them apart)."""
    a = _fibres(rng, (N, N), 1)
    b = (_fibres(rng, (N, N), 0) + _fibres(rng, (N, N), 1)) / np.sqrt(2)
    return a, b


def _fit(rng):
    a, b = _textures(rng)
    samples = Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [N, N]},
        {"label": 2, "start": [0, N], "stop": [N, 2 * N]}]})
    return RecommendedModel(max_scale=4).fit(np.concatenate([a, b], 1), samples)


@pytest.mark.parametrize("ndim", [2, 3])
def test_coherence_is_one_for_stripes_and_low_for_isotropic_noise(ndim):
    rng = np.random.default_rng(0)
    shape = (24,) * ndim
    stripes = np.broadcast_to(np.sin(np.arange(24) / 2.0), shape).astype(np.float32)
    noise = ndi.gaussian_filter(rng.normal(0, 1, shape), 1.0).astype(np.float32)
    inner = (slice(6, -6),) * ndim
    assert squared_coherence(stripes, 0, 2)[inner].min() > 0.99
    assert squared_coherence(noise, 0, 3)[inner].mean() < 0.2
    flat = np.zeros(shape, np.float32)            # no gradient at all: no direction, no NaN
    assert np.array_equal(squared_coherence(flat, 1, 2), flat)


def test_coherence_only_from_level_3_so_tissue_levels_are_unchanged():
    assert [coherence_pairs(j) for j in range(3)] == [[], [], []]
    assert coherence_pairs(5) == [(0, 1), (0, 2), (1, 2), (1, 3), (2, 3)]


@pytest.mark.parametrize("ndim", [2, 3])
def test_features_do_not_change_when_the_image_is_turned_or_transposed(ndim):
    rng = np.random.default_rng(3)
    img = rng.normal(0, 1, (19, 23, 21)[:ndim]).astype(np.float32)
    feats, names = multiscale_features(img, 4)
    assert any(n.startswith("coh") for n in names)
    turns = [lambda a: np.swapaxes(a, 0, 1), lambda a: np.flip(a, 0),
             lambda a: np.rot90(a, 1, axes=(0, 1))]
    if ndim == 3:
        turns.append(lambda a: np.moveaxis(a, 2, 0))
    for turn in turns:
        moved, _ = multiscale_features(np.ascontiguousarray(turn(img)), 4)
        np.testing.assert_allclose(moved, turn(feats), atol=2e-4)


def test_labels_of_a_turned_flipped_or_transposed_image_are_turned_with_it():
    rng = np.random.default_rng(4)
    model = _fit(rng)
    a, b = _textures(rng)
    # a mosaic with an oblique boundary, so every turn moves it
    mask = np.add.outer(np.arange(N), np.arange(2 * N)) < 1.2 * N
    test = np.where(mask, np.concatenate([a, a], 1), np.concatenate([b, b], 1))
    labels = model.predict(test)
    assert len(np.unique(labels)) == 2
    for turn, back in [(np.transpose, np.transpose), (np.flipud, np.flipud),
                       (np.fliplr, np.fliplr), (np.rot90, lambda x: np.rot90(x, -1))]:
        np.testing.assert_array_equal(back(model.predict(np.ascontiguousarray(turn(test)))),
                                      labels)


@pytest.mark.parametrize("coherence", [True, False])
def test_fibres_turned_by_90_degrees_stay_the_same_material(coherence, monkeypatch):
    if not coherence:        # the features before coherence: this pair is out of their reach
        monkeypatch.setattr(_window_features, "COHERENCE_SPANS", ())
    rng = np.random.default_rng(0)
    model = _fit(rng)
    assert any(n.startswith("coh") for n in model.feature_names) == coherence
    a, b = _textures(rng)
    test = np.concatenate([a.T, b], 1)          # the fibres now run along y
    dice = dice_scores(model.predict(test), np.repeat([[1] * N + [2] * N], N, 0))
    if coherence:
        assert min(dice.values()) > 0.95
    else:
        assert max(dice.values()) < 0.8


def test_model_files_saved_before_coherence_still_predict_as_they_did(tmp_path):
    import json

    from napari_swa_imesh.segmentation import load_model

    rng = np.random.default_rng(5)
    a, b = _textures(rng)
    samples = Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [N, N]},
        {"label": 2, "start": [0, N], "stop": [N, 2 * N]}]})
    old = RecommendedModel(max_scale=4)
    old.coherence = False                     # as fitted before the coherence features
    old.fit(np.concatenate([a, b], 1), samples)
    old.scale = 4                             # a stack where coherence would shift columns
    path = old.save(tmp_path / "old.npz")
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    assert meta.pop("coherence") is False
    np.savez(tmp_path / "older.npz", meta=json.dumps(meta), **arrays)   # no such key then
    loaded = load_model(tmp_path / "older.npz")
    assert loaded.coherence is False
    test = np.concatenate([_textures(rng)[1], a.T], 1)
    np.testing.assert_array_equal(loaded.predict(test), old.predict(test))
    assert load_model(_fit(rng).save(tmp_path / "new.npz")).coherence is True
