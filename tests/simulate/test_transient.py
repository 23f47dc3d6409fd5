"""Transient diffusion: conservation, the steady limit, an analytic series, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.simulate import simulate, simulate_transient


def _checker(shape, materials=(1, 2)):
    """Two materials in a voxel checkerboard: every voxel its own leaf (a fine mesh)."""
    parity = np.indices(shape).sum(axis=0) % 2
    return np.where(parity == 0, materials[0], materials[1]).astype(np.uint8)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("shape", [(12, 14), (6, 7, 8)])
def test_insulated_box_conserves_the_amount(shape, order):
    rng = np.random.default_rng(sum(shape) + order)
    labels = rng.integers(1, 4, size=shape).astype(np.uint8)
    r = simulate_transient(labels, {1: 1.0, 2: 5.0, 3: 0.2}, duration=3.0, steps=6,
                           capacity={1: 1.0, 2: 2.0, 3: 0.5}, initial={1: 0.0, 2: 1.0, 3: 0.3},
                           order=order)
    total = sum(r.amount.values())
    counts = np.bincount(labels.reshape(-1), minlength=4)
    start = counts[2] * 2.0 * 1.0 + counts[3] * 0.5 * 0.3     # int c u of the start
    assert total[0] == pytest.approx(start, rel=1e-9)
    assert np.allclose(total, start, rtol=1e-8)
    assert r.values.shape == (7, len(r.mesh.points))
    # the substance spreads: material 1 (none at first) gains, material 2 loses
    assert r.amount[1][-1] > r.amount[1][0] and r.amount[2][-1] < r.amount[2][0]


def test_a_long_run_reaches_the_steady_potential():
    rng = np.random.default_rng(4)
    labels = rng.integers(1, 3, size=(10, 12)).astype(np.uint8)
    k = {1: 1.0, 2: 4.0}
    steady = simulate(labels, k, axes="x", order=1, adapt=0)
    # on the steady run's mesh: from the labels the transient run meshes finer where its
    # error estimate asks (2.4 % estimated on this mesh, the steady P1 error)
    r = simulate_transient(steady.mesh, k, duration=2000.0, steps=40,
                           fixed={"xmin": 0.0, "xmax": 1.0})
    assert np.allclose(r.values[-1], steady.potential["x"], atol=1e-6)


def test_front_in_a_bar_follows_the_series_solution():
    """u(0) = 1, insulated at x = L, u = 0 at t = 0: the classic Fourier series."""
    n, length, c, k, t_end = 40, 1.0, 2.0, 0.5, 0.3
    labels = _checker((2, n))
    r = simulate_transient(labels, {1: k, 2: k}, capacity=c, duration=t_end, steps=600,
                           fixed={"xmin": 1.0}, spacing=length / n)
    x = r.mesh.points[:, 1]
    series = np.ones_like(x)
    for m in range(200):
        q = (2 * m + 1) * np.pi / (2 * length)
        series -= 4 / ((2 * m + 1) * np.pi) * np.sin(q * x) * np.exp(-q * q * k / c * t_end)
    assert np.abs(r.values[-1] - series).max() < 5e-3


def test_capacity_and_time_scale_together():
    labels = np.random.default_rng(1).integers(1, 3, size=(8, 9)).astype(np.uint8)
    a = simulate_transient(labels, {1: 1.0, 2: 3.0}, capacity=1.0, duration=1.0, steps=5,
                           initial={1: 1.0, 2: 0.0}, fixed={"ymax": 0.0})
    b = simulate_transient(labels, {1: 1.0, 2: 3.0}, capacity=2.0, duration=2.0, steps=5,
                           initial={1: 1.0, 2: 0.0}, fixed={"ymax": 0.0})
    assert np.allclose(a.values, b.values, atol=1e-9)
    assert np.allclose(b.times, 2 * a.times)


@pytest.mark.parametrize("kwargs, message", [
    ({"duration": 0.0}, "duration must be a positive"),
    ({"duration": float("inf")}, "duration must be a finite number"),
    ({"duration": "1"}, "duration must be a finite number"),
    ({"steps": 0}, "steps must be a positive whole"),
    ({"steps": 2.5}, "steps must be a positive whole"),
    ({"fixed": {"zmin": 1.0}}, "unknown face 'zmin'"),
    ({"fixed": {"xmin": float("nan")}}, "fixed on xmin must be a finite number"),
    ({"capacity": {1: 1.0, 2: 0.0}}, "capacity must be positive"),
    ({"capacity": {1: 1.0, 9: 1.0}}, "not in the mesh"),
    ({"initial": {1: 1.0, 9: 1.0}}, "initial value names material 9"),
    ({"capacity": {"steel": 1.0}}, "capacity names material 'steel'"),
    ({"capacity": {1: float("nan")}}, "capacity of material 1 must be a finite"),
    ({"save_every": 0}, "save_every"),
    ({"order": 3}, "order must be 1 or 2"),
])
def test_bad_transient_options_are_refused(kwargs, message):
    labels = np.ones((6, 6), dtype=np.uint8)
    labels[:, 3:] = 2
    options = {"duration": 1.0, "steps": 2, **kwargs}
    with pytest.raises(ValueError, match=message):
        simulate_transient(labels, {1: 1.0, 2: 1.0}, **options)


def test_saved_frames_are_the_field_at_their_times():
    labels = _checker((2, 16))
    r = simulate_transient(labels, {1: 1.0, 2: 1.0}, duration=4.0, steps=8,
                           initial={1: 0.0, 2: 0.0}, fixed={"xmin": 1.0})
    x = r.mesh.points[:, 1]
    assert np.allclose(r.values[0][x > 0], 0.0)                 # the start, not the end
    changes = np.abs(np.diff(r.values, axis=0)).max(axis=1)
    assert np.all(changes > 1e-3)                               # every frame differs
    # the front advances (at x = 2: at x = 8 the first frames are at 1e-6 and below, where
    # the consistent mass undershoots by as much ahead of the front)
    assert np.all(np.diff(r.values[:, x == 2].mean(axis=1)) > 0)


def test_p1_start_stays_within_its_values_and_p2_nearly():
    labels = np.random.default_rng(3).integers(1, 3, size=(10, 11)).astype(np.uint8)
    for order, slack in ((1, 1e-12), (2, 0.05)):
        r = simulate_transient(labels, {1: 1.0, 2: 1.0}, duration=1.0, steps=1,
                               initial={2: 1.0}, order=order)
        assert r.values[0].min() >= -slack and r.values[0].max() <= 1 + slack


def test_a_fixed_face_without_material_is_refused():
    labels = np.full((6, 8), 2, dtype=np.uint8)
    labels[:, 0] = 1                                            # 1 covers xmin
    with pytest.raises(ValueError, match="no meshed material touches the xmin face"):
        simulate_transient(labels, {2: 1.0}, duration=1.0, steps=2, fixed={"xmin": 1.0},
                           exclude=[1])


def test_names_work_for_every_per_material_option_and_the_mesh_is_not_modified():
    from napari_swa_imesh.mesh import mesh_labels

    labels = np.ones((6, 6), dtype=np.uint8)
    labels[:, 3:] = 2
    mesh = mesh_labels(labels)
    r = simulate_transient(mesh, {"a": 1.0, "b": 2.0}, capacity={"b": 3.0},
                           initial={"a": 1.0}, duration=1.0, steps=2,
                           material_names={1: "a", 2: "b"})
    assert mesh.material_names == {}
    total = r.amount[1] + r.amount[2]
    assert np.allclose(total, 18.0)                  # 18 px of a at 1, capacity 1
