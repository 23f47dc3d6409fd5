"""Refining for the interval by its own gap (``simulate._certify.plan_refinement``).

* the gap per element decides: graded steps where it lies in voxel-sized elements (blobs),
  interface refinement where it lies in large flat leaves (a checkerboard's squares);
* a lower bound of an earlier mesh of the same labels is kept when the finer mesh's is
  weaker (both bound the same k_eff), and the reference stays inside;
* a 3-D mesh solved for grading (its curl left to the last mesh) but not graded after
  all gets the curl;
* the curl's flux is the exact curl of a quadratic field; the masked conjugate gradients
  are the restricted system's, step for step.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse
from simulate_cases import blobs, checkerboard

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import _certify as certify
from napari_swa_imesh.simulate import simulate
from napari_swa_imesh.simulate._assembly import fe_space
from napari_swa_imesh.simulate._conductivity import conductivity_tensors
from napari_swa_imesh.simulate._curl import CurlBound, _pcg
from napari_swa_imesh.simulate._dual import dual_bound
from napari_swa_imesh.simulate._solve import SolverInfo

K = {1: 1.0, 2: 10.0, 3: 0.1}


def test_the_gap_in_voxel_elements_is_graded_in_flat_leaves_refined_at_interfaces():
    fine = mesh_labels(checkerboard(8, 1))        # every leaf is one pixel
    flat = mesh_labels(checkerboard(2, 8))        # four 8 x 8 leaves
    assert certify.voxel_share(fine, np.ones(fine.n_cells)) == 1.0
    assert certify.voxel_share(flat, np.ones(flat.n_cells)) == 0.0
    assert certify.voxel_share(flat, np.zeros(flat.n_cells)) == 1.0   # nothing to place
    plan = dict(order=2, may_refine=True, growth_seen=1.0, memory=4e9, interval=True)
    graded = certify.plan_refinement(fine, checkerboard(8, 1), 1, np.ones(fine.n_cells),
                                     **plan)
    assert graded.why is None and graded.target > len(fine.points)
    assert graded.leaf_gap.sum() == pytest.approx(fine.n_cells)
    assert "where the gap is largest" in graded.message
    uniform = certify.plan_refinement(flat, checkerboard(2, 8), 1, np.ones(flat.n_cells),
                                      **plan)
    assert uniform.why is None and uniform.target is None and uniform.level == 1
    kept = certify.plan_refinement(flat, checkerboard(2, 8), 1, np.ones(flat.n_cells),
                                   **{**plan, "may_refine": False})
    assert "adapt was given" in kept.why


def test_graded_steps_close_the_interval_around_a_finer_reference():
    lab = blobs((16, 16), seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first = simulate(lab, K, axes="x", adapt=1, gap=0.01)     # kept as asked
        r = simulate(lab, K, axes="x", gap=0.01)
        reference = simulate(lab, K, axes="x", order=2, adapt=0, refine=3, gap=np.inf)
    lo, hi = r.interval["x"]
    assert first.certify == 0 and r.certify >= 1
    assert r.gap["x"] < 0.7 * first.gap["x"]
    # graded: the mesh is the adaptive step's tree split again, not interface refinement
    assert r.mesh.recipe.adapted is not None and r.mesh.recipe.adapted.steps == 1 + r.certify
    # both intervals hold the labels' k_eff, so each bound lies below the other's upper
    ref_lo, ref_hi = reference.interval["x"]
    assert lo < ref_hi and ref_lo < hi


def test_an_earlier_sharper_lower_bound_is_kept(monkeypatch):
    # no grading, and a curl space that admits the adaptive step's mesh only: the finer
    # mesh of interface refinement has the Crouzeix-Raviart bound alone, lower than the
    # curl's on the coarser mesh, which is kept
    lab = blobs((6, 6, 6), seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # the default's mesh, kept (adapt given)
        first = simulate(lab, K, axes="x", adapt=1, gap=1e-4)
    monkeypatch.setattr(certify, "CURL_NODES", fe_space(first.mesh, 2).n_dofs)
    monkeypatch.setitem(certify.GRADED_UNKNOWNS, 3, 1)
    monkeypatch.setitem(certify.CERTIFY_UNKNOWNS, 3, int(4.5 * first.dofs))  # one step
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(lab, K, axes="x", gap=1e-4)
        alone = simulate(r.mesh, K, axes="x", order=2, gap=1e-4)
    assert r.certify == 1 and r.mesh.recipe.adapted is None     # interface refinement
    assert r.interval["x"][0] == pytest.approx(first.interval["x"][0], rel=1e-12)
    assert alone.interval["x"][0] < r.interval["x"][0] < r.interval["x"][1]


def test_the_flux_is_the_exact_curl_of_a_quadratic_field():
    mesh = mesh_labels(blobs((3, 4, 3), seed=0))
    space = fe_space(mesh, 2)
    rng = np.random.default_rng(4)
    q, m = rng.standard_normal((3, 3, 3)), rng.standard_normal((3, 3))

    def field(x):             # A_k = x . Q_k x + M_k . x, (n, 3)
        return np.einsum("ni,kij,nj->nk", x, q, x) + x @ m.T

    def curl(x):              # d_j A_k = ((Q_k + Q_k^T) x + M_k)_j
        g = np.einsum("kij,nj->nki", q + q.transpose(0, 2, 1), x) + m[None]   # (n, k, j)
        return np.stack([g[:, 2, 1] - g[:, 1, 2], g[:, 0, 2] - g[:, 2, 0],
                         g[:, 1, 0] - g[:, 0, 1]], axis=1)

    potential = field(space.doflocs.T).ravel()         # node i, component k at 3 i + k
    base = rng.standard_normal((mesh.n_cells, 3))
    bound = CurlBound(1.0, potential, base, 2.0, space, SolverInfo(0, 0, 0.0, 0.0), 0)
    lam = rng.dirichlet(np.ones(4), size=2)
    s, vol = bound.fluxes(slice(0, mesh.n_cells), lam)                  # (2, 3, M)
    for i in range(2):
        x = np.einsum("p,mpj->mj", lam[i], mesh.points[mesh.cells])
        np.testing.assert_allclose(s[i].T, 2.0 * (curl(x) + base), rtol=1e-10, atol=1e-10)
    assert vol.sum() == pytest.approx(np.prod(mesh.image_box()[1]))


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2 ** 16), share=st.floats(0.2, 0.9))
def test_masked_conjugate_gradients_are_the_restricted_system(seed, share):
    rng = np.random.default_rng(seed)
    n = 60
    a = sparse.random(n, n, density=0.1, random_state=rng)
    matrix = (a @ a.T + sparse.eye(n)).tocsr()
    free = rng.random(n) < share
    free[0] = True
    rhs = np.where(free, rng.standard_normal(n), 0.0)
    # 8 steps: short of convergence, where the two differ by their rounding only
    x, steps, residual = _pcg(matrix, rhs, 8, 1.0, 0.0, free)
    y, steps2, residual2 = _pcg(matrix[free][:, free], rhs[free], 8, 1.0, 0.0)
    assert steps == steps2 == 8
    np.testing.assert_allclose(x[free], y, rtol=1e-8, atol=1e-12)
    assert not x[~free].any()
    assert residual == pytest.approx(residual2, rel=1e-6)


def test_a_mesh_solved_for_grading_but_not_graded_gets_the_curl(monkeypatch):
    # a 3-D board of 4-voxel cubes: its gap lies in flat leaves, so the step would be
    # interface refinement, refused here by its cap: the curl skipped for grading is
    # computed on the mesh that stays
    squares = np.arange(8) // 4
    lab = (np.add.outer(np.add.outer(squares, squares), squares) % 2 + 1).astype(np.uint8)
    monkeypatch.setitem(certify.CERTIFY_UNKNOWNS, 3, 1)
    with pytest.warns(UserWarning, match="interval's refinement may take"):
        r = simulate(lab, {1: 1.0, 2: 10.0}, axes="x", gap=1e-4)
    assert r.certify == 0
    assert certify.grades(r.mesh, lab, True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # a mesh: solved sharp from the start
        sharp = simulate(r.mesh, {1: 1.0, 2: 10.0}, axes="x", order=2, gap=1e-4)
    materials, cell_material = np.unique(r.mesh.material, return_inverse=True)
    tensors = conductivity_tensors({1: 1.0, 2: 10.0}, materials, 3, r.mesh.material_names)
    lo, hi = r.mesh.image_box()
    cr = dual_bound(r.mesh, fe_space(r.mesh, 1), tensors, cell_material, 2, lo, hi,
                    tol=1e-10).k_lower
    assert cr < r.interval["x"][0] < r.interval["x"][1]
    assert r.interval["x"][0] == pytest.approx(sharp.interval["x"][0], rel=1e-9)
