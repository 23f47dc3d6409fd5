"""Hashin-Shtrikman bounds: the formulas against independent ones, their trace form on
periodic tensors (laminates attain both trace bounds in 2-D), and where they apply."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from napari_swa_imesh.cli import main
from napari_swa_imesh.simulate import simulate
from napari_swa_imesh.simulate._hashin import (
    HashinShtrikman,
    hashin_shtrikman,
    two_isotropic_phases,
)


def maxwell_garnett(k_matrix: float, k_inclusion: float, f_inclusion: float, d: int) -> float:
    """Maxwell Garnett / Clausius-Mossotti mixing, written in its own textbook form."""
    k1, k2, f = k_matrix, k_inclusion, f_inclusion
    return k1 * (k2 + (d - 1) * k1 + (d - 1) * f * (k2 - k1)) / (k2 + (d - 1) * k1 - f * (k2 - k1))


@settings(max_examples=60, deadline=None)
@given(st.floats(0.01, 100), st.floats(1.0001, 1000), st.floats(0.001, 0.999),
       st.sampled_from([2, 3]))
def test_bounds_are_maxwell_garnett_with_either_phase_as_matrix(k1, ratio, f2, d):
    k2 = k1 * ratio
    lower, upper = hashin_shtrikman(k1, k2, f2, d)
    assert lower == pytest.approx(maxwell_garnett(k1, k2, f2, d), rel=1e-10)
    assert upper == pytest.approx(maxwell_garnett(k2, k1, 1 - f2, d), rel=1e-10)
    harmonic = 1 / ((1 - f2) / k1 + f2 / k2)
    arithmetic = (1 - f2) * k1 + f2 * k2
    assert harmonic < lower < upper < arithmetic


@settings(max_examples=40, deadline=None)
@given(st.floats(0.1, 10), st.floats(1.01, 100), st.floats(0.01, 0.99), st.sampled_from([2, 3]))
def test_an_isotropic_tensor_at_a_scalar_bound_meets_its_trace_bound(k1, ratio, f2, d):
    k2 = k1 * ratio
    lower, upper = hashin_shtrikman(k1, k2, f2, d)
    at_lower = HashinShtrikman.of(k1, k2, f2, d, lower * np.eye(d))
    assert at_lower.trace_lower[0] == pytest.approx(at_lower.trace_lower[1], rel=1e-9)
    at_upper = HashinShtrikman.of(k1, k2, f2, d, upper * np.eye(d))
    assert at_upper.trace_upper[0] == pytest.approx(at_upper.trace_upper[1], rel=1e-9)
    assert at_upper.trace_holds == (True, True)


def test_a_tensor_below_the_lower_trace_bound_is_refused():
    lower, _ = hashin_shtrikman(1.0, 10.0, 0.5, 3)
    with pytest.raises(ValueError, match="Hashin-Shtrikman lower trace bound"):
        HashinShtrikman.of(1.0, 10.0, 0.5, 3, lower * 0.99 * np.eye(3))
    # the trace form bounds the sum: one low eigenvalue with high others can be fine
    assert HashinShtrikman.of(1.0, 10.0, 0.5, 3, np.diag([lower * 0.99, 5.0, 5.0])
                              ).trace_holds[0]
    # above the upper bound is reported, not refused
    _, upper = hashin_shtrikman(1.0, 10.0, 0.5, 3)
    hs = HashinShtrikman.of(1.0, 10.0, 0.5, 3, upper * 1.01 * np.eye(3))
    assert hs.trace_holds == (True, False)


def test_two_phases_only_isotropic_and_filling_the_box():
    iso = np.stack([np.eye(2), 4 * np.eye(2)])
    assert two_isotropic_phases(iso, np.array([0.25, 0.75])) == (1.0, 4.0, 0.75)
    assert two_isotropic_phases(iso[::-1], np.array([0.25, 0.75])) == (1.0, 4.0, 0.25)
    assert two_isotropic_phases(iso, np.array([0.25, 0.70])) is None        # a void
    assert two_isotropic_phases(np.stack([np.eye(2)] * 3), np.ones(3) / 3) is None
    assert two_isotropic_phases(np.stack([np.diag([1.0, 2.0]), np.eye(2)]),
                                np.array([0.5, 0.5])) is None


def test_2d_periodic_laminate_attains_both_trace_bounds():
    # a simple laminate is optimal in 2-D: both trace inequalities are equalities, so a
    # wrong bound formula or a wrong tensor shows at once
    lab = np.ones((8, 8), np.uint8)
    lab[:, 4:] = 2
    r = simulate(lab, {1: 1.0, 2: 10.0}, protocol="periodic")
    hs = r.hashin_shtrikman
    assert hs is not None and hs.f_high == pytest.approx(0.5)
    assert hs.trace_lower[0] == pytest.approx(hs.trace_lower[1], rel=1e-7)
    assert hs.trace_upper[0] == pytest.approx(hs.trace_upper[1], rel=1e-7)
    # along the layers the mixed k_eff is the arithmetic mean, above the scalar upper
    # bound: why the scalar interval is information and the trace form the test
    mixed = simulate(lab, {1: 1.0, 2: 10.0}, axes="y")
    assert mixed.k_eff["y"] == pytest.approx(5.5, rel=1e-8) and mixed.k_eff["y"] > hs.upper


def disks(n: int, fraction: float, radius: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lab = np.ones((n, n), np.uint8)
    yy, xx = np.mgrid[:n, :n] + 0.5
    while np.mean(lab == 2) < fraction:
        cy, cx = rng.uniform(0, n, 2)
        lab[(yy - cy) ** 2 + (xx - cx) ** 2 <= radius ** 2] = 2
    return lab


@pytest.mark.parametrize("seed", [0, 1])
def test_random_disks_periodic_tensor_lies_within_the_bounds(seed):
    lab = disks(48, 0.3, 4.5, seed)
    r = simulate(lab, {1: 1.0, 2: 10.0}, protocol="periodic", order=2)
    hs = r.hashin_shtrikman
    assert hs.trace_holds == (True, True)
    # nearly isotropic disks: each axis inside the scalar interval, closer to the lower
    # bound (disks in a matrix are the lower bound's coated-cylinder geometry)
    for value in r.k_eff.values():
        assert hs.lower < value < hs.upper
        assert value - hs.lower < hs.upper - value


def test_json_reports_the_bounds_for_two_phases_and_not_for_three(tmp_path, capsys):
    lab = disks(24, 0.3, 3.5, 2)
    np.save(tmp_path / "two.npy", lab)
    assert main(["simulate", str(tmp_path / "two.npy"), "-k", "1=1", "2=10",
                 "--protocol", "periodic", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    hs = out["hashin_shtrikman"]
    assert hs["trace_lower"]["holds"] and hs["trace_upper"]["holds"]
    assert hs["lower"] == pytest.approx(hashin_shtrikman(1, 10, float(np.mean(lab == 2)), 2)[0])
    three = lab.copy()
    three[:4] = 3
    np.save(tmp_path / "three.npy", three)
    assert main(["simulate", str(tmp_path / "three.npy"), "-k", "1=1", "2=10", "3=2",
                 "--json"]) == 0
    assert "hashin_shtrikman" not in json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("k2", [1 + 1e-13, 1 + 1e-10, 1 + 1e-7, 1.001])
def test_nearly_equal_phases_do_not_trip_the_lower_trace_check(k2):
    # K - k1 is then round-off: no inequality can be read from it (the check stands down
    # below 1e-6 and widens its slack as k2 / (k2 - k1) above)
    lab = disks(16, 0.4, 3.0, 3)
    r = simulate(lab, {1: 1.0, 2: k2}, protocol="periodic", order=1, adapt=0)
    hs = r.hashin_shtrikman
    assert hs.lower <= hs.upper
    if k2 - 1 <= 1e-6:
        assert hs.trace_holds is None
    else:
        assert hs.trace_holds[0]
