import numpy as np
import pytest

from napari_swa_imesh.segmentation import (
    Samples,
    SWAModel,
    dice_scores,
    load_model,
    segment,
    segment_steps,
    sieve_labels,
    tile_placement,
    upsample_tiles,
)


def two_textures(shape=(70, 45), seed=0):
    """Left part quiet (std 1), right part rough (std 3); non-dyadic on purpose."""
    rng = np.random.default_rng(seed)
    truth = np.ones(shape, np.int32)
    truth[..., shape[-1] // 2:] = 2
    img = rng.normal(0, 1, shape) * np.where(truth == 1, 1.0, 3.0) + 10
    half = shape[-1] // 2
    lead = tuple([0] * (len(shape) - 1))
    stop = tuple(n for n in shape[:-1])
    s = Samples.from_dict({
        "materials": [{"label": 1, "name": "quiet"}, {"label": 2, "name": "rough"}],
        "boxes": [{"label": 1, "start": list(lead) + [0], "stop": list(stop) + [half - 2]},
                  {"label": 2, "start": list(lead) + [half + 2],
                   "stop": list(stop) + [shape[-1]]}]})
    return img, truth, s


@pytest.mark.parametrize("shape", [(70, 45), (20, 24, 32)])
def test_segment_recovers_two_textures_at_input_shape(shape):
    img, truth, s = two_textures(shape)
    before = img.copy()
    res = segment(img, s, method="reference", scale=2)
    np.testing.assert_array_equal(img, before)
    assert res.labels.shape == img.shape
    assert res.tile_labels.shape == tuple(-(-n // 4) for n in shape)
    np.testing.assert_array_equal(res.labels, upsample_tiles(res.tile_labels, 2, img.shape))
    dice = dice_scores(res.labels, truth)
    assert min(dice.values()) > 0.9
    assert 0 <= res.eps_l < 10
    assert res.eps_m == pytest.approx(-4 * res.eps_l / 100)
    sig = {row["label"]: row for row in res.signatures}
    assert sig[2]["variance_mean"] > 4 * sig[1]["variance_mean"]
    assert sig[1]["mean_mean"] == pytest.approx(10, abs=0.3)


def test_default_scale_is_the_suggested_res():
    img, truth, s = two_textures((64, 128))
    res = segment(img, s, method="reference")
    assert res.res is not None and res.scale == res.res.suggested_scale


def test_progress_steps_and_result():
    img, truth, s = two_textures()
    gen = segment_steps(img, s, method="reference", scale=1)
    steps = []
    while True:
        try:
            steps.append(next(gen))
        except StopIteration as stop:
            result = stop.value
            break
    assert steps[-1][0] == steps[-1][1] and len(steps) >= 4
    assert result.labels.shape == img.shape


@pytest.mark.parametrize("features,classifier", [("F1", "md"), ("F1", "lvq"), ("F5", "gm"),
                                                 ("F7", "gm")])
def test_model_save_load_applies_identically(tmp_path, features, classifier):
    img, truth, s = two_textures((64, 64))
    res = segment(img, s, method="reference", scale=2, feature_set=features,
                  classifier=classifier)
    p = res.model.save(tmp_path / "m.npz")
    model = load_model(p)
    assert model.scale == 2 and model.feature_set == features
    assert [m.name for m in model.materials] == ["quiet", "rough"]
    other, _, _ = two_textures((64, 64), seed=5)
    np.testing.assert_array_equal(model.predict_tiles(other), res.model.predict_tiles(other))
    with pytest.raises(FileExistsError, match="force"):
        res.model.save(p)
    with pytest.raises(ValueError, match="fitted on 2-D"):
        model.predict_tiles(np.zeros((8, 8, 8)))


def test_model_file_is_not_a_pickle(tmp_path):
    img, truth, s = two_textures((64, 64))
    p = segment(img, s, method="reference", scale=2).model.save(tmp_path / "m.npz")
    with np.load(p, allow_pickle=False) as data:
        assert "meta" in data.files


def test_tile_placement_centres_tiles_over_pixels():
    scale, translate = tile_placement(3, (2.0, 0.5))
    assert scale == (16.0, 4.0)
    # tile 0 covers pixels 0..7, whose centres are at 0..7 * spacing: the middle is 3.5
    assert translate == (7.0, 1.75)


def test_sieve_against_brute_force():
    rng = np.random.default_rng(0)
    lab = np.ones((30, 30), int)
    lab[10:20, 10:20] = 2
    lab[3, 3] = 2            # a speck of 1 tile
    lab[25:27, 25:27] = 3    # a 4-tile island
    out = sieve_labels(lab, 5)
    assert out[3, 3] == 1 and (out[25:27, 25:27] == 1).all()
    assert (out[10:20, 10:20] == 2).all()
    assert sieve_labels(lab, 4)[25, 25] == 3
    _ = rng


def test_errors_are_clear():
    img, truth, s = two_textures((64, 64))
    ref = {"method": "reference"}
    with pytest.raises(ValueError, match="full tile"):
        segment(img, s, scale=6, **ref)
    with pytest.raises(ValueError, match="F1"):
        segment(img, s, scale=2, feature_set="F9", **ref)
    with pytest.raises(ValueError, match="either sample boxes"):
        segment(img)
    for method in ("reference", "recommended"):
        with pytest.raises(ValueError, match="NaN"):
            bad = img.copy()
            bad[0, 0] = np.nan
            segment(bad, s, scale=2, method=method)
        with pytest.raises(ValueError, match="RGB"):
            segment(np.zeros((64, 64, 3), np.uint8), s, scale=2, method=method)
        with pytest.raises(ValueError, match="outside"):
            segment(img[:30], s, scale=2, method=method)
    with pytest.raises(ValueError, match="not fitted"):
        SWAModel(scale=1).predict_tiles(img)
    with pytest.raises(ValueError, match="choose 0"):
        segment(img, s, scale=9, **ref)
    with pytest.raises(ValueError, match="max_scale must be 0..8"):
        segment(img, s, scale=9)


@pytest.mark.parametrize("features", ["F1", "F2", "F5"])
def test_signatures_are_the_moments_of_the_classified_tiles(features):
    from napari_swa_imesh.segmentation import material_signatures, tile_moments

    img, truth, s = two_textures((64, 64))
    res = segment(img, s, method="reference", scale=2, feature_set=features)
    moments, counts = tile_moments(img, 2)
    expected = material_signatures(moments, counts, res.tile_labels, res.model.materials)
    for row in expected:
        row["scale"] = 2            # a stochastic run reads its tile size from this column
    assert res.signatures == expected


@pytest.mark.parametrize("method", ["reference", "recommended"])
def test_describe_is_the_one_summary(method):
    img, truth, s = two_textures((64, 64))
    res = segment(img, s, method=method)
    text = res.describe()
    assert text.splitlines()[0].startswith(f"{method} method: scale")
    assert f"eps_l = {res.eps_l:.2f}%" in text
    for m in res.model.materials:
        assert f"  {m.name}: " in text
    if method == "recommended":
        per_scale = res.pixels_per_scale()
        assert sum(per_scale.values()) == img.size and list(per_scale) == list(res.scales)[
            :len(per_scale)]
        assert "pixels labelled per scale" in text
    res.notes.append("a note")
    assert res.describe().endswith("warning: a note")
    assert "a note" not in res.describe(notes=False)


def test_validated_once_and_input_untouched_for_float32():
    img, truth, s = two_textures((48, 40))
    img32 = img.astype(np.float32)
    before = img32.copy()
    res = segment(img32, s)
    np.testing.assert_array_equal(img32, before)
    np.testing.assert_array_equal(res.labels, segment(img32.astype(np.float64), s).labels)
