"""The 2-D stream-function lower bound (:mod:`napari_swa_imesh.simulate._stream`).

* with P1 it is the Crouzeix-Raviart / RT0 bound (the divergence-free RT0 fields are the
  rotated gradients of P1), with P2 it is sharper;
* it is Keller's reciprocity on the discrete level: the bound along x with conductivities
  k is one over the primal along y with 1 / k;
* it stays below a finer reference on random blobs, with holes, and with a loose solve;
* its hypercircle sums to the gap.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from simulate_cases import blobs, checkerboard

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import simulate
from napari_swa_imesh.simulate._assembly import fe_space
from napari_swa_imesh.simulate._conductivity import conductivity_tensors
from napari_swa_imesh.simulate._dual import dual_bound
from napari_swa_imesh.simulate._stream import stream_bound

K = {1: 1.0, 2: 10.0, 3: 0.1}


def _setup(mesh, conductivity):
    materials, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = conductivity_tensors(conductivity, materials, mesh.ndim, mesh.material_names)
    lo, hi = mesh.image_box()
    return tensors, cell_material, lo, hi


def _stream(mesh, conductivity, axis, order, tol=1e-10):
    tensors, cell_material, lo, hi = _setup(mesh, conductivity)
    return stream_bound(mesh, fe_space(mesh, order), tensors, cell_material, axis, lo, hi,
                        tol=tol)


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 999), st.integers(0, 1))
def test_p1_is_the_crouzeix_raviart_bound_and_p2_is_sharper(seed, axis):
    mesh = mesh_labels(blobs((7, 9), seed=seed))
    tensors, cell_material, lo, hi = _setup(mesh, K)
    cr = dual_bound(mesh, fe_space(mesh, 1), tensors, cell_material, axis, lo, hi,
                    tol=1e-12).k_lower
    p1 = _stream(mesh, K, axis, 1, tol=1e-12).k_lower
    p2 = _stream(mesh, K, axis, 2, tol=1e-12).k_lower
    assert p1 == pytest.approx(cr, rel=1e-8)
    assert p2 > cr * (1 + 1e-6)


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 999), st.sampled_from([1, 2]))
def test_keller_reciprocity(seed, order):
    """The stream problem along x is the primal along y with the inverse conductivities
    (isotropic, a box without holes): the two numbers multiply to one exactly."""
    lab = blobs((6, 8), seed=seed)
    mesh = mesh_labels(lab)
    lower = _stream(mesh, K, 1, order, tol=1e-12).k_lower
    inverse = {m: 1 / v for m, v in K.items()}
    upper = simulate(mesh, inverse, axes="y", order=order, adapt=0, tol=1e-12,
                     interval=False).k_eff["y"]
    assert lower * upper == pytest.approx(1.0, rel=1e-8)


ANISOTROPIC = {1: [[2.0, 0.7], [0.7, 1.0]], 2: 10.0, 3: [[0.1, 0.0], [0.0, 0.5]]}


@pytest.mark.parametrize("seed, conductivity", [(0, K), (4, ANISOTROPIC)])
def test_below_a_finer_reference(seed, conductivity):
    lab = blobs((8, 10), seed=seed)
    coarse = simulate(lab, conductivity, order=2, adapt=0, gap=np.inf)
    fine = simulate(lab, conductivity, order=2, adapt=0, refine=3, interval=False)
    for name, (lo, hi) in coarse.interval.items():
        assert lo < fine.k_eff[name] < hi


def test_a_loose_solve_still_bounds():
    mesh = mesh_labels(blobs((8, 10), seed=2))
    tight = _stream(mesh, K, 1, 2, tol=1e-12).k_lower
    loose = _stream(mesh, K, 1, 2, tol=0.3).k_lower
    assert 0 < loose <= tight * (1 + 1e-12)


def test_holes_keep_a_free_constant():
    """An excluded blob inside the box (insulated, touching no side) and one cutting the
    bottom side: the interval holds a finer solve."""
    labels = np.ones((10, 12), dtype=np.uint8)
    labels[3:6, 4:7] = 4
    labels[:2, 8:10] = 4
    labels[6:, :3] = 2
    k = {1: 1.0, 2: 20.0}
    r = simulate(labels, k, exclude=[4], order=2, adapt=0, gap=np.inf)
    fine = simulate(labels, k, exclude=[4], order=2, adapt=0, refine=3, interval=False)
    for name, (lo, hi) in r.interval.items():
        assert 0 < lo < fine.k_eff[name] < hi


def test_a_cut_box_has_the_zero_bound():
    """An excluded wall from the bottom side to the top one separates the x faces."""
    labels = np.ones((6, 9), dtype=np.uint8)
    labels[:, 4] = 2
    mesh = mesh_labels(labels, exclude=[2])
    assert _stream(mesh, {1: 1.0}, 1, 2).k_lower == 0.0


def test_hypercircle_sums_to_the_gap():
    lab = blobs((9, 11), seed=4)
    mesh = mesh_labels(lab)
    r = simulate(mesh, K, axes="x", order=2, adapt=0, gap=np.inf, tol=1e-12)
    bound = _stream(mesh, K, 1, 2, tol=1e-12)
    assert bound.k_lower == pytest.approx(r.interval["x"][0], rel=1e-9)
    tensors, cell_material, lo, hi = _setup(mesh, K)
    space = fe_space(mesh, 2)
    from napari_swa_imesh.simulate._assembly import stiffness_matrix
    from napari_swa_imesh.simulate._protocols import face_dofs
    from napari_swa_imesh.simulate._solve import solve_dirichlet

    low = face_dofs(space.doflocs, lo, hi, "xmin")
    high = face_dofs(space.doflocs, lo, hi, "xmax")
    values, _ = solve_dirichlet(stiffness_matrix(space, tensors, cell_material),
                                np.concatenate([low, high]),
                                np.concatenate([np.zeros(low.size), np.ones(high.size)]),
                                tol=1e-12)
    eta = bound.hypercircle(space, values, tensors, cell_material)
    gap = (r.interval["x"][1] - r.interval["x"][0]) * (hi[0] - lo[0]) / (hi[1] - lo[1])
    assert eta.min() >= 0
    assert eta.sum() == pytest.approx(gap, rel=1e-6)


def _periodic(labels, conductivity, **kw):
    return simulate(labels, conductivity, protocol="periodic", order=2, adapt=0, **kw)


def test_periodic_laminate_interval_is_exact():
    labels = np.ones((6, 10), np.uint8)
    labels[:, 3:] = 2
    labels[:, 7:] = 3
    r = _periodic(labels, {1: 1.0, 2: 7.0, 3: 0.2})
    layers = np.array([3, 4, 3]) / 10
    exact = {"x": 1 / np.sum(layers / np.array([1.0, 7.0, 0.2])),
             "y": np.sum(layers * np.array([1.0, 7.0, 0.2]))}
    for name, (lo, hi) in r.interval.items():
        assert lo == pytest.approx(exact[name], rel=1e-10)
        assert hi == pytest.approx(exact[name], rel=1e-10)
    assert "certified x" in r.describe() and "interval" in r.summary()


def test_periodic_checkerboard_holds_dykhne_and_blobs_a_finer_solve():
    board = checkerboard(4, 3)
    with pytest.warns(UserWarning, match="periodic interval along"):
        r = _periodic(board, {1: 1.0, 2: 10.0})
    for lo, hi in r.interval.values():
        assert lo < np.sqrt(10.0) < hi
    lab = blobs((8, 10), seed=3)
    with pytest.warns(UserWarning, match="periodic interval along"):
        coarse = _periodic(lab, K)
    fine = _periodic(lab, K, refine=1, interval=False)
    for name, (lo, hi) in coarse.interval.items():
        assert lo < fine.k_eff[name] < hi
    assert not fine.interval and "no certified interval" in fine.describe()
