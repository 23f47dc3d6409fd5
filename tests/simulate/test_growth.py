"""Reaction-diffusion on the mesh (issue 28, part 1): verification against theory.

* Fisher-KPP's travelling wave moves at 2 sqrt(D rho) (measured late, where Bramson's
  logarithmic lag of a compact seed, -3/(2t) sqrt(D / rho), is below 1 %);
* in a two-material slab the front runs ahead in the white-matter strip, at a speed
  between the two materials' own;
* the drug's steady profile from a fixed face is exp(-x sqrt(lambda / D));
* the errors fall under refinement in space (second order) and in the asked time error;
* c stays within [0, 1] and the amount's balance closes, for any rate, seed and kill
  windows (hypothesis), and a uniform tumour under chemotherapy follows the logistic ODE.
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_swa_imesh.simulate._growth import simulate_growth


def _front(result, k, row=0.0, threshold=0.5):
    """x of the c = threshold crossing along the mesh line at y = row (mesh coords)."""
    pts = result.mesh.points
    on = np.isclose(pts[:, 0], row)
    x, c = pts[on, 1], result.values[k][on]
    order = np.argsort(x)
    x, c = x[order], c[order]
    i = int(np.flatnonzero(c < threshold)[0])
    return x[i - 1] + (c[i - 1] - threshold) / (c[i - 1] - c[i]) * (x[i] - x[i - 1])


@pytest.fixture(scope="module")
def wave():
    # a 1-D-like slab: D = rho = 1 (front width 1), h = 1/4 of it
    labels = np.ones((1, 840), dtype=np.uint8)
    return simulate_growth(labels, {1: 1.0}, rate=1.0, seed=((0.0, 0.125), 2.0),
                           duration=100.0, saves=5, spacing=(0.25, 0.25), error=3e-3)


def test_travelling_wave_speed_is_two_sqrt_d_rho(wave):
    times = wave.times
    k60, k100 = int(np.flatnonzero(times == 60)[0]), int(np.flatnonzero(times == 100)[0])
    speed = (_front(wave, k100) - _front(wave, k60)) / 40.0
    assert abs(speed / 2.0 - 1) < 0.02
    # and the lag is Bramson's, not an error of the scheme: within 0.5 % of 2 - 1.5 ln(5/3)/40
    assert abs(speed / (2.0 - 1.5 * np.log(100 / 60) / 40) - 1) < 0.005


def test_wave_stays_bounded_and_balanced(wave):
    assert wave.values.min() >= 0.0 and wave.values.max() <= 1.0
    residual = np.abs(wave.balance_residual).max() / wave.amount.max()
    assert residual < 1e-9
    # the growth term is the amount gained (nothing else acts)
    assert np.allclose(wave.amount - wave.amount[0], wave.balance["growth"]
                       + wave.balance["clipping"], rtol=1e-9, atol=1e-9)


def test_front_runs_ahead_in_the_white_matter_strip():
    # rows 0..3: white matter D = 4, rows 4..7: grey matter D = 1 (rho = 1); strips
    # about one front width thick, so one front, led by the white matter, at the speed of
    # the layered medium's mean diffusivity along the layers, 2 sqrt(2.5), far above grey
    # matter's own 2
    labels = np.full((8, 130), 3, dtype=np.uint8)
    labels[:4] = 2
    h = 0.5
    r = simulate_growth(labels, {2: 4.0, 3: 1.0}, rate=1.0, seed=((0.0, 2.0), 2.0),
                        duration=16.0, saves=2, spacing=(h, h), error=3e-3,
                        front_cells=2.0)
    wm = [_front(r, k, row=0.0) for k in (1, 2)]
    gm = [_front(r, k, row=8 * h) for k in (1, 2)]
    speed_wm, speed_gm = (wm[1] - wm[0]) / 8.0, (gm[1] - gm[0]) / 8.0
    assert wm[1] > gm[1] + 0.2                  # ahead in white matter
    assert speed_gm == pytest.approx(speed_wm, rel=0.01)
    assert speed_wm == pytest.approx(2.0 * np.sqrt(2.5), rel=0.02)
    assert r.values.min() >= 0 and r.values.max() <= 1


def _drug(n, duration=40.0, decay=1.0, d=1.0, length=10.0, front_cells=4.0):
    labels = np.ones((1, n), dtype=np.uint8)
    h = length / n
    return simulate_growth(labels, {1: d}, model="drug", decay=decay,
                           fixed={"xmin": 1.0}, duration=duration, saves=2,
                           spacing=(h, h), error=1e-4, front_cells=front_cells)


def _drug_error(r):
    pts = r.mesh.points
    x, c = pts[:, 1], r.values[-1]
    exact = np.exp(-x)                        # sqrt(lambda / D) = 1; L = 10 far off
    near = x <= 3.0
    return np.max(np.abs(c - exact)), np.max(np.abs(c[near] / exact[near] - 1))


def test_drug_steady_profile_is_exponential_decay():
    r = _drug(80)
    absolute, relative = _drug_error(r)
    assert absolute < 0.01 and relative < 0.01
    # the inflow through the fixed face balances the decay in the steady state
    flux = np.diff(r.balance["boundary"])[-1]
    decay = -np.diff(r.balance["decay"])[-1]
    assert flux == pytest.approx(decay, rel=1e-3)
    assert np.abs(r.balance_residual).max() < 1e-9 * r.amount.max()


def test_space_error_is_second_order():
    # a bound of one element per width: the voxels (h = 1/2, 1/4) are the elements
    runs = [_drug(n, duration=30.0, front_cells=1.0) for n in (20, 40)]
    assert [r.mesh.n_cells for r in runs] == [40, 80]
    errors = [_drug_error(r)[0] for r in runs]
    assert 3.2 < errors[0] / errors[1] < 4.8


def test_time_error_falls_with_the_asked_error():
    labels = np.ones((1, 60), dtype=np.uint8)

    def run(error):
        return simulate_growth(labels, {1: 1.0}, rate=1.0, seed=((0.0, 0.25), 2.0),
                               duration=5.0, saves=1, spacing=(0.25, 0.25),
                               error=error).values[-1]
    reference = run(1e-5)
    errors = [np.abs(run(e) - reference).max() for e in (1e-2, 1e-3, 1e-4)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < errors[0] / 10
    assert errors[1] < 1e-2


def test_uniform_tumour_under_chemotherapy_follows_the_logistic_ode():
    labels = np.ones((4, 4), dtype=np.uint8)
    rho, kill = 0.5, 1.5
    r = simulate_growth(labels, {1: 1.0}, rate=rho, seed=((2.0, 2.0), 10.0),
                        kill=[(1.0, 3.0, kill)], duration=4.0, saves=4, error=1e-6,
                        front_cells=1.0)
    # dc/dt = (rho - k) c - rho c^2 from c = 1 on [1, 3], logistic growth from 1 before
    a = rho - kill
    t = 2.0
    exact = a / (rho - (rho - a) * np.exp(-a * t))
    assert np.allclose(r.values[1], 1.0)
    assert r.values[3] == pytest.approx(np.full(r.values.shape[1], exact), rel=1e-4)
    assert r.balance["kill"][-1] < 0
    assert np.abs(r.balance_residual).max() < 1e-9 * r.amount.max()


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rate=st.floats(0.1, 5.0), d=st.floats(0.05, 2.0), x=st.floats(0.5, 7.5),
       y=st.floats(0.5, 5.5), kill=st.floats(0.0, 8.0))
def test_c_stays_within_bounds_and_the_balance_closes(rate, d, x, y, kill):
    labels = np.ones((6, 8), dtype=np.uint8)
    labels[:, 5:] = 2
    r = simulate_growth(labels, {1: d, 2: 3 * d}, rate=rate, seed=((x, y), 1.0),
                        kill=[(0.5, 1.0, kill)], duration=2.0, saves=2, error=1e-2,
                        front_cells=1.0)
    assert r.values.min() >= 0.0 and r.values.max() <= 1.0
    assert np.abs(r.balance_residual).max() <= 1e-9 * max(r.amount.max(), 1.0)


def test_materials_without_diffusivity_are_not_meshed():
    labels = np.ones((6, 8), dtype=np.uint8)
    labels[:, 6:] = 1
    labels[:, :2] = 4                          # CSF: D = 0, no flux into it
    r = simulate_growth(labels, {1: 0.5, 4: 0.0}, rate=1.0, seed=((4.0, 3.0), 1.5),
                        duration=2.0, saves=1, front_cells=1.0)
    assert set(np.unique(r.mesh.material)) == {1}
    assert r.mesh.points[:, 1].min() == pytest.approx(2.0)


@pytest.mark.parametrize("kwargs, match", [
    ({"rate": 0.0}, "positive proliferation rate"),
    ({"seed": None}, "seed ball"),
    ({"seed": ((100.0, 100.0), 0.5)}, "holds no vertex"),
    ({"model": "gompertz"}, "model must be one of"),
    ({"fixed": {"xmin": 1.0}}, "belong to the drug model"),
    ({"kill": [(2.0, 1.0, 1.0)]}, "kill window"),
    ({"error": 2.0}, "error must lie"),
])
def test_bad_arguments_say_what_to_do(kwargs, match):
    args = {"rate": 1.0, "seed": ((2.0, 2.0), 1.0), **kwargs}
    with pytest.raises(ValueError, match=match):
        simulate_growth(np.ones((4, 4), dtype=np.uint8), {1: 1.0}, duration=1.0, **args)


def test_a_face_flux_brings_its_amount_and_a_fixed_material_holds_its_value():
    labels = np.ones((4, 10), dtype=np.uint8)
    # no decay: the amount is the flux times the face's length times the time
    r = simulate_growth(labels, {1: 1.0}, model="drug", flux={"xmin": 0.5}, duration=3.0,
                        saves=3, front_cells=1.0)
    # (the extrapolation's undershoot ahead of the entering front is clipped: its own term)
    assert r.amount - r.balance["clipping"] == pytest.approx(0.5 * 4.0 * r.times, rel=1e-9,
                                                             abs=1e-12)
    assert 0 <= r.balance["clipping"][-1] < 1e-6
    assert r.balance["sources"][-1] == pytest.approx(6.0, rel=1e-9)
    # a vessel (material 2) held at 1 feeds the tissue around it against the decay
    labels[1:3, 4:6] = 2
    r = simulate_growth(labels, {1: 1.0, 2: 1.0}, model="drug", decay=0.5,
                        fixed={2: 1.0}, duration=2.0, saves=1, front_cells=1.0)
    vessel = np.unique(r.mesh.cells[r.mesh.material == 2])
    assert np.all(r.values[:, vessel] == 1.0)
    assert 0 < r.values[-1].min() < 1 and r.balance["boundary"][-1] > 0
    assert np.abs(r.balance_residual).max() < 1e-9 * r.amount.max()
