"""The real-anatomy development set of the benchmarks (benchmarks/anatomy.py)."""

import numpy as np
import pytest
from benchmarks import anatomy


def _box(crop):
    origin = anatomy._QUADRANTS[crop]
    return [(o, o + n) for o, n in zip(origin, anatomy.CROP)]


def test_validation_split_is_held_out():
    dev = [c for c in anatomy.SPLITS["dev"]]
    val = [c for c in anatomy.SPLITS["val"]]
    for crop_d, anat_d, seeds_d in dev:
        for crop_v, anat_v, seeds_v in val:
            overlap = [min(b[1], d[1]) - max(b[0], d[0])
                       for b, d in zip(_box(crop_d), _box(crop_v))]
            assert min(overlap) <= 0, f"{crop_d} and {crop_v} share voxels"
            assert anat_d != anat_v and not set(seeds_d) & set(seeds_v)


def test_case_is_a_labelled_rician_phantom():
    pytest.importorskip("nilearn")
    image, truth, brain = anatomy.make_case("sup-ant", 2, 0.09, 0.4, 0)
    assert image.shape == truth.shape == brain.shape == anatomy.CROP
    assert image.min() >= 0 and set(np.unique(truth)) == {0, 1, 2, 3}
    assert np.all(truth[~brain] == 0) and np.all(truth[brain] > 0)
    # tissue means keep the T1 order (CSF < GM < WM) through noise and bias
    means = [image[truth == k].mean() for k in (1, 2, 3)]
    assert means[0] < means[1] < means[2]
    d = anatomy.brain_dice(truth, truth, brain)
    assert d == {1: 1.0, 2: 1.0, 3: 1.0}
