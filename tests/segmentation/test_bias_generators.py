"""The held-out phantom generator (benchmarks/anatomy_heldout.py) is independent of the
tuning one (benchmarks/anatomy.py) and makes what it says."""

import numpy as np
import pytest
from benchmarks import anatomy, anatomy_heldout


def test_heldout_shares_no_crop_seed_or_contrast_with_tuning():
    dev = {c for c, _, _ in anatomy.SPLITS["dev"]}
    seeds = {a for split in anatomy.SPLITS.values() for _, a, _ in split}
    for crop, anat, _ in anatomy_heldout.CASES:
        assert crop not in dev and anat not in seeds
    assert not np.allclose(anatomy_heldout.MEANS, anatomy.MEANS)
    # the extent fits inside a quadrant at every spacing
    assert all(e <= n for e, n in zip(anatomy_heldout.CROP_MM, anatomy.CROP))


@pytest.mark.parametrize("spacing, contrast", [((1.0, 1.0, 1.0), "T1"),
                                               ((1.5, 0.94, 0.94), "T1"),
                                               ((1.0, 1.0, 1.0), "T2")])
def test_heldout_case_is_a_labelled_gaussian_phantom(spacing, contrast):
    pytest.importorskip("nilearn")
    image, truth, brain = anatomy_heldout.make_case("inf-ant", 7, 0.09, 0.4, spacing, 0,
                                                    contrast)
    shape = tuple(int(e // s) for e, s in zip(anatomy_heldout.CROP_MM, spacing))
    assert image.shape == truth.shape == brain.shape == shape
    assert set(np.unique(truth)) == {0, 1, 2, 3}
    assert np.all(truth[~brain] == 0) and np.all(truth[brain] > 0)
    means = [image[truth == k].mean() for k in (1, 2, 3)]
    assert (means[0] < means[1] < means[2]) == (contrast == "T1")
    assert (means[0] > means[1] > means[2]) == (contrast == "T2")
    # Gaussian, not Rician: the dark background goes below zero
    assert image[~brain].min() < 0


def test_heldout_tissue_intensity_depends_on_where_it_lies():
    # deep grey matter (far from CSF) is brighter than cortical (T1), white matter next to
    # grey darker than deep white: no class mean describes a whole class
    lab = np.full((40, 40, 40), 3, np.int8)
    lab[:, :, :4] = 1                       # CSF
    lab[:, :, 4:10] = 2                     # cortex
    lab[:, :, 30:] = 2                      # a deep nucleus, far from CSF
    out = anatomy_heldout._tissue_intensity(lab, anatomy_heldout.CONTRASTS["T1"])
    assert out[20, 20, 35] > out[20, 20, 5] + 0.03
    assert out[20, 20, 11] < out[20, 20, 20] - 0.02
    assert np.all(out[lab == 1] == anatomy_heldout.CONTRASTS["T1"][1])


def test_heldout_case_with_a_field_differs_from_its_flat_twin_by_the_field_alone():
    # the field has a random stream of its own: a case with a field is its flat twin times
    # a smooth field, with the same noise, so a bias variant is compared with like
    pytest.importorskip("nilearn")
    flat, truth, _ = anatomy_heldout.make_case("inf-ant", 7, 0.0, 0.0, (1.0, 1.0, 1.0), 0)
    biased, _, _ = anatomy_heldout.make_case("inf-ant", 7, 0.0, 0.4, (1.0, 1.0, 1.0), 0)
    noisy_flat, _, _ = anatomy_heldout.make_case("inf-ant", 7, 0.09, 0.0, (1.0, 1.0, 1.0), 0)
    noisy_biased, _, _ = anatomy_heldout.make_case("inf-ant", 7, 0.09, 0.4, (1.0, 1.0, 1.0),
                                                   0)
    inside = flat > 0.05
    field = biased[inside] / flat[inside]
    assert field.max() / field.min() > 1.15                     # there is a field
    noise_flat = noisy_flat - flat
    noise_biased = noisy_biased - biased
    np.testing.assert_allclose(noise_biased, noise_flat, atol=1e-5)
