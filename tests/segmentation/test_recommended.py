import json

import numpy as np
import pytest

from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import (
    RecommendedModel,
    Samples,
    SWAModel,
    dice_scores,
    load_model,
    multiscale_feature_names,
    multiscale_features,
    potts_mean_field,
    samples_from_truth,
    segment,
    segment_steps,
    upsample_tiles,
)
from napari_swa_imesh.segmentation._tiles import majority_tiles


def edge_image(shape=(48, 61), *, contrast="intensity", edge=None, seed=0):
    """Two materials split by a straight edge along the last axis (non-dyadic on purpose)."""
    rng = np.random.default_rng(seed)
    edge = shape[-1] // 2 + 3 if edge is None else edge
    truth = np.ones(shape, np.int32)
    truth[..., edge:] = 2
    noise = rng.normal(0, 1, shape)
    if contrast == "intensity":
        img = np.where(truth == 1, 10.0, 14.0) + noise
    else:                                   # same mean, texture (spread) differs
        img = 10 + noise * np.where(truth == 1, 1.0, 3.0)
    lead = [0] * (len(shape) - 1)
    stop = list(shape[:-1])
    s = Samples.from_dict({
        "materials": [{"label": 1, "name": "left"}, {"label": 2, "name": "right"}],
        "boxes": [{"label": 1, "start": lead + [0], "stop": stop + [edge - 6]},
                  {"label": 2, "start": lead + [edge + 6], "stop": stop + [shape[-1]]}]})
    return img, truth, s, edge


# -- features -------------------------------------------------------------------------------
def test_features_match_brute_force_windows():
    rng = np.random.default_rng(1)
    img = rng.normal(5, 2, (20, 23))
    feats, names = multiscale_features(img, 2)
    assert feats.shape == img.shape + (len(names),) and feats.dtype == np.float32
    assert names == multiscale_feature_names(2)
    r, c = 9, 11                              # interior: the 5x5 window needs no reflection
    win = img[r - 2:r + 3, c - 2:c + 3]
    assert feats[r, c, names.index("value")] == pytest.approx(img[r, c], rel=1e-6)
    assert feats[r, c, names.index("mean@2")] == pytest.approx(win.mean(), rel=1e-5)
    assert feats[r, c, names.index("logstd@2")] == pytest.approx(np.log(win.std()), abs=1e-4)


@pytest.mark.parametrize("level", [0, 1, 2])
def test_haar_energy_matches_brute_force(level):
    from napari_swa_imesh.segmentation._window_features import haar_energy

    rng = np.random.default_rng(level)
    row = rng.normal(0, 1, 13)
    s = 1 << level
    mirrored = np.pad(row, s, mode="symmetric")
    block = [mirrored[i + s:i + 2 * s].mean() for i in range(-s, 14)]   # block(i) at i + s
    detail = [block[i + s] - block[i] for i in range(14)]               # at i - 1/2
    want = [(detail[i] ** 2 + detail[i + 1] ** 2) / 2 for i in range(13)]
    np.testing.assert_allclose(haar_energy(row[None].astype(np.float32), level)[0], want,
                               atol=1e-5)


@pytest.mark.parametrize("ndim", [2, 3])
def test_features_are_centred(ndim):
    # flipping the image flips every feature: no half-pixel drift of any window or detail
    rng = np.random.default_rng(2)
    img = rng.normal(0, 1, (17,) * ndim)
    feats, _ = multiscale_features(img, 3)
    flipped, _ = multiscale_features(img[(slice(None, None, -1),) * ndim], 3)
    np.testing.assert_allclose(flipped[(slice(None, None, -1),) * ndim], feats, atol=2e-4)


def test_potts_mean_field_fixes_an_isolated_pixel_and_keeps_sure_pixels():
    ll = np.zeros((2, 9, 9), np.float32)
    ll[0] = 3.0                                # class 0 everywhere ...
    ll[1, 4, 4] = 4.0                          # ... but one pixel mildly prefers class 1
    q0 = potts_mean_field(ll, 0.0)
    assert q0[1, 4, 4] > 0.5
    q = potts_mean_field(ll, 2.0)
    assert q[0, 4, 4] > 0.9
    np.testing.assert_allclose(q.sum(axis=0), 1, rtol=1e-5)


def test_majority_tiles():
    labels = np.array([[1, 1, 2], [1, 2, 2], [2, 2, 2]])
    np.testing.assert_array_equal(majority_tiles(labels, 1, [1, 2]), [[1, 2], [2, 2]])


# -- the method -----------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [(48, 61), (14, 20, 27)])
def test_full_resolution_output_aligned_with_the_input(shape):
    img, truth, s, _ = edge_image(shape)
    before = img.copy()
    res = segment(img, s)
    np.testing.assert_array_equal(img, before)
    assert res.method == "recommended"
    assert res.labels.shape == img.shape and res.labels.dtype == np.int32
    assert res.level.shape == img.shape
    assert res.tile_labels.shape == tuple(-(-n // (1 << res.scale)) for n in shape)
    assert min(dice_scores(res.labels, truth).values()) > 0.97


def test_straight_intensity_edge_recovered_within_one_pixel():
    img, truth, s, edge = edge_image((64, 80), contrast="intensity")
    labels = segment(img, s).labels
    far = np.abs(np.arange(img.shape[-1]) - (edge - 0.5)) > 1.0
    np.testing.assert_array_equal(labels[:, far], truth[:, far])


def test_straight_texture_edge_not_shifted():
    # same mean, spread 1 vs 3: the boundary found per row scatters, but its average sits
    # within one pixel of the true edge (windows are centred) and no row is far off
    img, truth, s, edge = edge_image((64, 96), contrast="texture", seed=3)
    labels = segment(img, s).labels
    found = (labels == 1).sum(axis=1)          # left material's extent per row
    assert abs(found.mean() - edge) <= 1.0
    assert np.abs(found - edge).max() <= 6


def test_reference_results_unchanged():
    img, truth, s, _ = edge_image((40, 52), contrast="texture")
    direct = SWAModel(scale=2, feature_set="F1", classifier="gm").fit(img, s)
    expected = upsample_tiles(direct.predict_tiles(img), 2, img.shape)
    np.testing.assert_array_equal(direct.predict(img), expected)
    for kwargs in ({"scale": 2}, {"scale": 2, "feature_set": "F1", "classifier": "gm"}):
        res = segment(img, s, method="reference", **kwargs)
        assert res.method == "reference" and isinstance(res.model, SWAModel)
        np.testing.assert_array_equal(res.labels, expected)
        assert res.eps_l == direct.scores["eps_l"]


def test_scale_alone_keeps_the_recommended_method():
    # the method is explicit: a scale is the recommended model's largest scale
    img, truth, s, _ = edge_image((40, 52), contrast="texture")
    res = segment(img, s, scale=2)
    assert res.method == "recommended" and max(res.scales) <= 2


def test_segment_steps_keeps_its_signature_and_progress():
    img, truth, s, _ = edge_image()
    gen = segment_steps(img, s, scale=None, feature_set=None, classifier=None, sieve=0,
                        model=None, spacing=(1.0, 1.0))
    steps = []
    while True:
        try:
            steps.append(next(gen))
        except StopIteration as stop:
            res = stop.value
            break
    assert [d for d, _, _ in steps] == [0, 1, 2, 3, 4, 5] and steps[0][1] == 5
    assert res.method == "recommended" and res.model.spacing == (1.0, 1.0)
    summary = json.loads(json.dumps(res.summary()))
    assert summary["method"] == "recommended" and summary["scales"] == list(res.scales)
    assert set(summary["model"]["level_error"]) == {str(j) for j in res.model.level_error}
    assert summary["model"]["top_features_fisher"]


def test_model_round_trip(tmp_path):
    img, truth, s, _ = edge_image((40, 50), contrast="texture")
    fitted = segment(img, s)
    path = fitted.model.save(tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
    assert meta["method"] == "recommended" and meta["materials"][0]["name"] == "left"
    loaded = load_model(path)
    assert isinstance(loaded, RecommendedModel)
    assert loaded.scales == fitted.model.scales and loaded.labels == [1, 2]
    again = segment(img, model=loaded)
    np.testing.assert_array_equal(again.labels, segment(img, model=fitted.model).labels)
    # reference files still load as reference models
    ref = segment(img, s, method="reference", scale=2).model.save(tmp_path / "ref.npz")
    assert isinstance(load_model(ref), SWAModel)


def test_bias_robustness_on_a_small_phantom():
    dice = {}
    for bias in (0.0, 0.4):
        img, truth = tissue_phantom((40, 56, 56), noise=0.03, bias=bias, seed=4)
        s = samples_from_truth(truth, scale=1, per_material=6)
        res = segment(img, s)
        dice[bias] = dice_scores(res.labels, truth)
        if bias:
            assert res.model.bias_correction
    for m in (1, 2, 3):
        assert dice[0.4][m] > 0.9
        assert dice[0.4][m] >= dice[0.0][m] - 0.02


# -- errors ---------------------------------------------------------------------------------
def test_error_paths(tmp_path):
    img, truth, s, _ = edge_image()
    with pytest.raises(ValueError, match="feature_set belong to the reference method"):
        segment(img, s, method="recommended", feature_set="F2")
    with pytest.raises(ValueError, match="classifier belong to the reference method"):
        segment(img, s, classifier="md")
    with pytest.raises(ValueError, match="unknown method"):
        segment(img, s, method="best")
    fitted = segment(img, s).model
    with pytest.raises(ValueError, match="fitted with the 'recommended' method"):
        segment(img, model=fitted, method="reference")
    with pytest.raises(ValueError, match="not fitted"):
        RecommendedModel().predict(img)
    with pytest.raises(ValueError, match="2-D images; got a 3-D"):
        fitted.predict(img[None].repeat(3, axis=0))
    with pytest.raises(ValueError, match="bias_correction must be"):
        RecommendedModel(bias_correction="yes")
    with pytest.raises(ValueError, match="max_scale must be"):
        RecommendedModel(max_scale=12)
    tiny = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [1, 2]},
                                        {"label": 2, "start": [0, 50], "stop": [20, 60]}]})
    with pytest.raises(ValueError, match="at least 4 are needed"):
        segment(img, tiny)
    with pytest.raises(ValueError, match="end in .npz"):
        fitted.save(tmp_path / "m.pkl")


# -- command line ---------------------------------------------------------------------------
def test_cli_method_rule_and_res_plot(tmp_path, capsys):
    from napari_swa_imesh.cli import main
    from napari_swa_imesh.segmentation import save_samples

    img, truth, s, _ = edge_image((48, 64), contrast="texture")
    np.save(tmp_path / "img.npy", img)
    np.save(tmp_path / "truth.npy", truth)
    save_samples(s, tmp_path / "s.json")
    base = ["segment", tmp_path / "img.npy", "--samples", tmp_path / "s.json", "--truth",
            tmp_path / "truth.npy", "--json", "--force"]

    def run(*extra):
        assert main([str(a) for a in base + list(extra)]) == 0
        return json.loads(capsys.readouterr().out)

    out = run("-o", tmp_path / "a.npy", "--res-plot", tmp_path / "res.png",
              "--model-out", tmp_path / "m.npz")
    assert out["method"] == "recommended" and out["model"]["coarse_scale"] == out["scale"]
    assert (tmp_path / "res.png").stat().st_size > 0
    assert run("-o", tmp_path / "b.npy", "--scale", 2)["method"] == "recommended"
    assert run("-o", tmp_path / "c.npy", "--classifier", "md", "--method", "reference"
               )["method"] == "reference"
    assert run("-o", tmp_path / "d.npy", "--scale", 3, "--method", "recommended"
               )["method"] == "recommended"
    applied = main([str(a) for a in ["segment", tmp_path / "img.npy", "--model",
                                     tmp_path / "m.npz", "-o", tmp_path / "e.npy", "--json"]])
    assert applied == 0
    assert json.loads(capsys.readouterr().out)["method"] == "recommended"
    for extra in (["--method", "recommended", "--features", "F2"], ["--classifier", "md"]):
        code = main([str(a) for a in base + ["-o", tmp_path / "f.npy"] + extra])
        err = capsys.readouterr().err
        assert code == 2 and "belong to the reference method" in err
        assert err.count("\n") == 1 and not (tmp_path / "f.npy").exists()
