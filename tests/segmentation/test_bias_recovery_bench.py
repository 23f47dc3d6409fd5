"""The recovery benchmark's measures (benchmarks/bench_bias_recovery.py) mean what its
table says: recovery is the share of the lost Dice won back, the true field is the ratio
of the noise-free images."""

import numpy as np
import pytest
from benchmarks.bench_bias_recovery import recovery, true_field


@pytest.mark.parametrize("corrected, expected", [(0.80, 0.0), (0.90, 1.0), (0.85, 0.5),
                                                 (0.95, 1.5)])
def test_recovery_is_the_share_of_the_lost_dice_won_back(corrected, expected):
    assert recovery(corrected, off=0.80, clean=0.90) == pytest.approx(expected)


def test_recovery_is_undefined_when_the_field_costs_nothing():
    assert np.isnan(recovery(0.91, off=0.90, clean=0.9005))


def test_true_field_is_the_ratio_and_air_takes_its_nearest_value():
    rng = np.random.default_rng(0)
    clean = rng.uniform(0.2, 1.0, (6, 7, 8)).astype(np.float32)
    clean[:, :, :2] = 0                                     # air: no field defined
    field = np.exp(np.linspace(-0.2, 0.2, 8, dtype=np.float32))[None, None, :] \
        * np.ones((6, 7, 1), np.float32)
    out = true_field(clean * field, clean)
    np.testing.assert_allclose(out[:, :, 2:], field[:, :, 2:], rtol=1e-6)
    np.testing.assert_allclose(out[:, :, :2], field[:, :, 2:3].repeat(2, 2), rtol=1e-6)
