"""Transient error control against the 1-D analytic front (issue 26).

A slab of one material, held at 1 on x = 0 from t = 0 and insulated elsewhere, long
enough to be semi-infinite: ``u = erfc(x / 2 sqrt(D t))`` and ``int c u = 2 c sqrt(D t / pi)``
per unit area. The IMESH octree alone coarsens the slab to a few elements.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import erfc

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import simulate_transient
from napari_swa_imesh.simulate._time_steps import FINEST_LEVEL, adaptive_euler


def _front_errors(r, k: float, c: float, index: int = -1) -> tuple[float, float]:
    """Max error of the field at the vertices and relative error of the amount."""
    t = r.times[index]
    d = k / c
    x = r.mesh.points[:, -1]
    error = float(np.abs(r.values[index] - erfc(x / (2 * np.sqrt(d * t)))).max())
    area = float(np.prod(np.asarray(r.mesh.shape[:-1]) * np.asarray(r.mesh.spacing[:-1])))
    amount = sum(a[index] for a in r.amount.values()) / area
    return error, amount / (2 * c * np.sqrt(d * t / np.pi)) - 1


def _quiet(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return simulate_transient(*args, **kwargs)


@pytest.mark.parametrize("shape", [(8, 64), (4, 4, 48)])
@pytest.mark.parametrize("k, c", [(1.0, 1.0), (2.0, 0.5)])
def test_front_within_one_percent_where_the_diffusion_length_is_four_voxels(shape, k, c):
    t = 16.0 * c / k                                   # sqrt(D t) = 4 voxels
    labels = np.ones(shape, dtype=np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)    # no warning: the ask is met
        r = simulate_transient(labels, {1: k}, capacity=c, duration=t, steps=1,
                               fixed={"xmin": 1.0})
    error, amount = _front_errors(r, k, c)
    assert error <= 0.01 and abs(amount) <= 0.01
    # the estimate is reliable (not below the error) and within what was asked
    assert error <= r.error.relative() <= 0.01
    assert r.warnings == []


def test_without_error_control_the_same_slab_is_off_and_says_so():
    """The run as it was: 18 vertices, 9 % off at L = 4 voxels, amount +33 %."""
    labels = np.ones((8, 64), dtype=np.uint8)
    with pytest.warns(UserWarning, match=r"the estimated error .* % of the jump exceeds 1 %"):
        r = simulate_transient(labels, {1: 1.0}, duration=16.0, steps=4,
                               fixed={"xmin": 1.0}, error=None)
    error, amount = _front_errors(r, 1.0, 1.0)
    assert error > 0.05 and amount > 0.2
    assert r.error.relative() > 0.05                  # the estimate sees it
    assert r.error.asked is None and "fixed steps" in r.error.describe()


def test_asking_less_error_gives_less_error():
    labels = np.ones((8, 64), dtype=np.uint8)
    errors, vertices = [], []
    for asked in (0.03, 0.01, 0.004):
        r = _quiet(labels, {1: 1.0}, duration=4.0, steps=1, fixed={"xmin": 1.0},
                   error=asked)
        errors.append(_front_errors(r, 1.0, 1.0)[0])
        vertices.append(len(r.mesh.points))
        assert errors[-1] <= asked
    assert np.all(np.diff(errors) < 0) and np.all(np.diff(vertices) >= 0)


def test_error_falls_under_refinement_in_space():
    """Meshes given (no refinement of their own), steps adapted tightly: the error and
    its estimate fall with the element size, at about second order."""
    labels = np.ones((4, 48), dtype=np.uint8)
    errors, estimates = [], []
    for size in (4.0, 2.0, 1.0):
        mesh = mesh_labels(labels, max_size=size * np.sqrt(2))
        r = _quiet(mesh, {1: 1.0}, duration=16.0, steps=1, fixed={"xmin": 1.0},
                   error=0.002)
        errors.append(_front_errors(r, 1.0, 1.0)[0])
        estimates.append(np.nanmax(r.error.space))
    assert np.all(np.diff(errors) < 0) and np.all(np.diff(estimates) < 0)
    assert errors[0] / errors[-1] > 6                  # h^2: 16 for two halvings
    assert all(0.5 * e <= s <= 3 * e for e, s in zip(errors, estimates))


def test_error_falls_under_refinement_in_time():
    """Fixed implicit Euler steps on a fine mesh: halving the step halves the time
    error (first order), and the estimate follows it."""
    labels = np.ones((2, 48), dtype=np.uint8)
    mesh = mesh_labels(labels, refine=0, max_size=0.5 * np.sqrt(2) * 2)
    reference = _quiet(mesh, {1: 1.0}, duration=8.0, steps=1, fixed={"xmin": 1.0},
                       error=1e-4)
    errors, estimates = [], []
    for steps in (4, 8, 16):
        r = _quiet(mesh, {1: 1.0}, duration=8.0, steps=steps, fixed={"xmin": 1.0},
                   error=None)
        errors.append(float(np.abs(r.values[-1] - reference.values[-1]).max()))
        estimates.append(float(r.error.time[-1]))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(ratios > 1.6) and np.all(ratios < 2.5)
    assert all(e <= s for e, s in zip(errors, estimates))


def test_a_mesh_file_too_coarse_for_the_first_time_is_named():
    mesh = mesh_labels(np.ones((8, 64), dtype=np.uint8))
    with pytest.warns(UserWarning, match="the mesh file is too coarse"):
        r = simulate_transient(mesh, {1: 1.0}, duration=4.0, steps=1, fixed={"xmin": 1.0})
    assert r.error.relative() > 0.01
    assert len(r.warnings) == 1
    assert r.warnings[0].endswith(".") and ". " not in r.warnings[0]     # one sentence


def test_a_budget_too_small_for_the_ask_says_so():
    """A substance released everywhere at once (a fine random mixture) at a time when
    the diffusion length is a tenth of a voxel: no mesh within the budget resolves it."""
    labels = np.random.default_rng(0).integers(1, 3, size=(12, 12)).astype(np.uint8)
    with pytest.warns(UserWarning, match="could not be refined enough"):
        r = simulate_transient(labels, {1: 1.0, 2: 1.0}, duration=0.01, steps=1,
                               initial={1: 1.0})
    assert r.error.relative() > 0.01
    total = sum(r.amount.values())
    assert np.allclose(total, total[0], rtol=1e-8)   # still conserved


def test_uniform_data_have_no_error_and_no_warning():
    labels = np.ones((6, 6), dtype=np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        r = simulate_transient(labels, {1: 1.0}, duration=1.0, steps=2, initial=0.5,
                               fixed={"xmin": 0.5})
    assert np.allclose(r.values, 0.5) and r.error.relative() == 0.0


def test_dyadic_steps_end_exactly_on_the_saved_times():
    from scipy import sparse

    n = 30
    stiffness = sparse.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)],
                             [-1, 0, 1], format="csr")
    stiffness[0, 0] = stiffness[-1, -1] = 1.0
    mass = sparse.identity(n, format="csr")
    u = np.zeros(n)
    u[0] = 1.0
    free = np.ones(n, dtype=bool)
    free[0] = False
    records = list(adaptive_euler(mass, stiffness, u, free, base=0.5, saves=[1, 3, 4],
                                  duration=2.0, tol=1e-3, solver_tol=1e-12))
    assert [r.time for r in records] == [0.5, 1.5, 2.0]
    for r in records:
        level = np.log2(0.5 / r.step)
        assert level == int(level) and 0 <= level < FINEST_LEVEL
    assert records[-1].steps > 4
    assert np.all(records[-1].values >= -1e-12) and np.all(records[-1].values <= 1)
    assert records[0].values[0] == 1.0


@pytest.mark.parametrize("bad, message", [(0.0, "error must lie between 0 and 1"),
                                          (1.5, "error must lie between 0 and 1"),
                                          ("x", "error must be a finite number")])
def test_bad_error_is_refused(bad, message):
    with pytest.raises(ValueError, match=message):
        simulate_transient(np.ones((4, 4), dtype=np.uint8), {1: 1.0}, duration=1.0,
                           steps=1, error=bad)


def test_the_cli_prints_the_estimate_and_writes_it_beside_the_series(tmp_path, capsys):
    import json

    import h5py

    from napari_swa_imesh.cli import main

    path = tmp_path / "slab.npy"
    np.save(path, np.ones((8, 64), dtype=np.uint8))
    out = tmp_path / "s.xdmf"
    rc = main(["simulate", str(path), "-k", "1=1", "--transient", "16", "--steps", "2",
               "--fixed", "xmin=1", "-o", str(out)])
    stdout, err = capsys.readouterr()
    assert rc == 0 and err == ""
    assert "estimated max error" in stdout and "asked 1 %" in stdout
    with h5py.File(tmp_path / "s.h5") as h5:
        space, time, jump = h5["error/space"][()], h5["error/time"][()], h5["error/jump"][()]
    assert space.shape == time.shape == (3,) and jump == 1.0
    assert 0 < np.nanmax(space + time) <= 0.01
    rc = main(["simulate", str(path), "-k", "1=1", "--transient", "16", "--steps", "2",
               "--fixed", "xmin=1", "--error", "fixed", "--json"])
    stdout, err = capsys.readouterr()
    report = json.loads(stdout)
    assert rc == 0 and report["error"]["asked"] is None and report["error"]["estimate"] > 0.05
    assert "warning: the estimated error" in err and report["warnings"]
    rc = main(["simulate", str(path), "-k", "1=1", "--transient", "16", "--error", "much"])
    assert rc == 2 and "--error takes a share" in capsys.readouterr().err


@settings(max_examples=25, deadline=None)
@given(st.integers(3, 12), st.integers(0, 2 ** 32 - 1), st.sampled_from([0.0, 1e-2, 1e-4]))
def test_steps_keep_the_amount_of_an_insulated_chain(n, seed, tol):
    """Any conductances and capacities, adaptive or fixed steps: ``1' M u`` is kept
    (each implicit Euler solve keeps it, so does the extrapolation) and the saved times
    are the asked ones."""
    from scipy import sparse

    rng = np.random.default_rng(seed)
    g = rng.uniform(0.1, 10.0, n - 1)                       # conductance of each link
    diagonal = np.zeros(n)
    diagonal[:-1] += g
    diagonal[1:] += g
    stiffness = sparse.diags([-g, diagonal, -g], [-1, 0, 1], format="csr")
    mass = sparse.diags(rng.uniform(0.5, 2.0, n), format="csr")
    u = rng.uniform(0.0, 1.0, n)
    records = list(adaptive_euler(mass, stiffness, u, np.ones(n, dtype=bool), base=0.25,
                                  saves=[1, 2, 4], duration=1.0, tol=tol,
                                  solver_tol=1e-12))
    assert [r.time for r in records] == [0.25, 0.5, 1.0]
    start = float(mass.diagonal() @ u)
    for r in records:
        assert float(mass.diagonal() @ r.values) == pytest.approx(start, rel=1e-9)


def test_a_substance_released_across_an_interface_follows_the_analytic_front():
    """Material 2 (x < 32) starts at 1, material 1 at 0, equal diffusivity:
    ``u = erfc((x - 32) / 2L) / 2`` and ``L / sqrt(pi)`` per unit area has crossed."""
    labels = np.ones((8, 64), dtype=np.uint8)
    labels[:, :32] = 2
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        r = simulate_transient(labels, {1: 1.0, 2: 1.0}, duration=16.0, steps=1,
                               initial={2: 1.0})
    x = r.mesh.points[:, -1]
    error = float(np.abs(r.values[-1] - 0.5 * erfc((x - 32) / 8.0)).max())
    crossed = r.amount[1][-1] / 8 / (4 / np.sqrt(np.pi)) - 1
    assert error <= 0.01 and abs(crossed) <= 0.01
    assert error <= r.error.relative() <= 0.01
