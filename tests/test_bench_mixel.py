"""The mixel experiment's closed form (benchmarks/bench_mixel.py) is the integral it stands
for, and its far material and outside are found by distances (any material order, any
``x -> a x + b`` including ``a < 0``)."""

import numpy as np
import pytest
from benchmarks.bench_mixel import far_and_end, mixel_log_density
from scipy.integrate import quad
from scipy.stats import norm


@pytest.mark.parametrize("x", [-0.6, 0.0, 0.15, 0.5, 0.95, 1.2, 1.6])
def test_density_is_the_integral_over_the_fraction(x):
    num = quad(lambda a: norm.pdf(x, a * 1.0 + (1 - a) * 0.2, 0.1), 0, 1, epsabs=0,
               epsrel=1e-10)[0]
    got = np.exp(mixel_log_density(x, 1.0, 0.2, 0.1))
    assert got == pytest.approx(num, rel=1e-6)
    assert np.exp(mixel_log_density(x, 0.2, 1.0, 0.1)) == pytest.approx(got)
    assert np.all(np.isfinite(mixel_log_density([-40.0, 40.0], 1.0, 0.2, 0.1)))


@pytest.mark.parametrize("a, b", [(1.0, 0.0), (3.0, -2.0), (-1.0, 0.0), (-0.5, 7.0)])
@pytest.mark.parametrize("end", ["nearest", "outside"])
def test_far_material_is_found_by_distances(a, b, end):
    rng = np.random.default_rng(0)
    means = np.array([0.62, 1.0, 0.48])                   # the far one (1.0) second
    values = np.concatenate([rng.normal(m, 0.03, 2000) for m in (0.0, *means)])
    sds = np.full(3, 0.03)
    far, stop = far_and_end(a * values + b, a * means + b, abs(a) * sds, end)
    assert far == 1
    assert stop == pytest.approx(a * (0.62 if end == "nearest" else 0.0) + b, abs=0.01)
    assert far_and_end(values[2000:], means, sds, end) is None     # no outside
