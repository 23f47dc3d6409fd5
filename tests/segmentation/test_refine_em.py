"""The class means re-estimated inside the classified image (_refine_em): closer to the
materials' own means than the boxes', never worse Dice on two different phantom
generators, invariant to x -> a x + b and to relabelling, and not applied to textures."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage as ndi

from napari_swa_imesh.segmentation import (
    RecommendedModel,
    Samples,
    _recommended,
    dice_scores,
    samples_from_truth,
)

MEANS = np.array([0.0, 0.2, 0.55, 0.8])       # background, dark, middle, bright


def _layers(n=96):
    """Three materials in wavy bands (1 | 2 | 3), 2-D."""
    r, c = np.mgrid[:n, :n]
    wave = 4 * np.sin(r / 6.0)
    return np.where(c < n / 3 + wave, 1, np.where(c < 2 * n / 3 + wave, 2, 3))


def _hard_labels_psf(seed=0):
    """Generator 1: hard labels, the bright material darker within ~5 px of the middle
    one (the boxes are deep: their mean is not the material's), a blur, Gaussian noise."""
    truth = _layers()
    d = ndi.distance_transform_edt(truth != 2)
    img = MEANS[truth] - 0.12 * (truth == 3) * np.exp(-d / 5.0)
    img = ndi.gaussian_filter(img, 0.7)
    img += 0.05 * np.random.default_rng(seed).standard_normal(img.shape)
    return img.astype(np.float32), truth


def _probability_mixing(seed=0):
    """Generator 2: soft tissue probabilities (smoothed one-hot), intensity their mix,
    Rician noise; the truth is the most probable material."""
    onehot = np.stack([(_layers() == k).astype(float) for k in (1, 2, 3)])
    prob = ndi.gaussian_filter(onehot, (0, 4.0, 4.0))
    truth = prob.argmax(0) + 1
    clean = np.tensordot(MEANS[1:], prob, axes=1)
    rng = np.random.default_rng(seed)
    s = 0.06
    img = np.hypot(clean + s * rng.standard_normal(clean.shape),
                   s * rng.standard_normal(clean.shape))
    return img.astype(np.float32), truth


def _fit(img, samples, refine=True, **options):
    if not refine:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(_recommended, "refine_fitted", lambda m, s: {"applied": False})
            return _fit(img, samples, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)        # scale notes
        return RecommendedModel(bias_correction=False, **options).fit(img, samples)


def _mean_dice(model, img, truth):
    return float(np.mean(list(dice_scores(model.predict(img), truth).values())))


@pytest.mark.parametrize("make", [_hard_labels_psf, _probability_mixing])
def test_refined_means_are_the_materials_and_never_cost_dice(make):
    img, truth = make()
    samples = samples_from_truth(truth, scale=2, per_material=3)
    refined, boxed = _fit(img, samples), _fit(img, samples, refine=False)
    info = refined.scores["refined_means"]
    assert info["applied"] and not boxed.scores["refined_means"]["applied"]
    # the means moved towards each material's own mean (standardised units)
    offset, scale = refined.intensity
    own = np.array([(img[truth == k].mean() - offset) / scale for k in (1, 2, 3)])
    box, new = np.array(info["box_mean"]), np.array(info["mean"])
    assert np.abs(new - own).sum() < np.abs(box - own).sum()
    assert _mean_dice(refined, img, truth) >= _mean_dice(boxed, img, truth)


def test_refinement_gains_where_the_boxes_are_atypical():
    # generator 1 is built so that the deep boxes misplace the middle | bright boundary
    img, truth = _hard_labels_psf()
    samples = samples_from_truth(truth, scale=2, per_material=3)
    gain = (_mean_dice(_fit(img, samples), img, truth)
            - _mean_dice(_fit(img, samples, refine=False), img, truth))
    assert gain > 0.001         # measured: .0017 (.9911 -> .9928)


@settings(max_examples=4, deadline=None)
@given(a=st.floats(0.01, 1000.0), b=st.floats(-1000.0, 1000.0))
def test_invariant_to_affine_intensity(a, b):
    img, truth = _hard_labels_psf()
    samples = samples_from_truth(truth, scale=2, per_material=3)
    ref = _fit(img, samples).predict(img)
    moved = (a * img.astype(np.float64) + b).astype(np.float64)
    assert (_fit(moved, samples).predict(moved) == ref).mean() >= 0.999


@settings(max_examples=3, deadline=None)
@given(perm=st.permutations([4, 9, 17]))
def test_invariant_to_relabelling(perm):
    img, truth = _probability_mixing()
    samples = samples_from_truth(truth, scale=2, per_material=3)
    ref = _fit(img, samples).predict(img)
    lut = {1: perm[0], 2: perm[1], 3: perm[2]}
    relabelled = Samples.from_dict({"boxes": [
        {"label": lut[b.label], "start": list(b.start), "stop": list(b.stop)}
        for b in samples.boxes]})
    out = _fit(img, relabelled).predict(img)
    np.testing.assert_array_equal(out, np.vectorize(lut.get)(ref))


def test_not_applied_to_textures():
    # calm | busy noise of one mean: the pixel value alone cannot tell them apart
    rng = np.random.default_rng(1)
    img = np.concatenate([rng.normal(10, 1, (64, 64)), rng.normal(10, 3, (64, 64))], 1)
    samples = Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [64, 56]},
        {"label": 2, "start": [0, 72], "stop": [64, 128]}]})
    model = _fit(img, samples, max_scale=4, pixels_per_material=3000)
    boxed = _fit(img, samples, refine=False, max_scale=4, pixels_per_material=3000)
    assert model.finest_scale > 0 and not model.scores["refined_means"]["applied"]
    for j, clf in model.levels.items():
        np.testing.assert_array_equal(clf.means_, boxed.levels[j].means_)
