"""The half-storage P2 stiffness and its two-level solve against the assembled path.

The references are independent of :mod:`._pmultigrid`: the symmetric CSR matrix of
:func:`stiffness_matrix` (its own layout of the same upper triangle), scipy's sparse LU
on the reduced system, and :func:`simulate` with the assembled matrix swapped back in.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse
from scipy.sparse.linalg import eigsh, spsolve
from simulate_cases import blobs

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import _amg, _simulate, simulate
from napari_swa_imesh.simulate._assembly import fe_space, p1_embedding, stiffness_matrix
from napari_swa_imesh.simulate._pmultigrid import (
    LANCZOS_MARGIN,
    P2Stiffness,
    TwoLevelDirichlet,
    p2_stiffness,
)
from napari_swa_imesh.simulate._solve import DirichletSolver

K3 = {1: 1.0, 2: 10.0, 3: 0.1}          # contrast 100, as the benchmark's blobs


def _tensors(d: int, values=(1.0, 10.0, 0.1)) -> np.ndarray:
    return np.array(values)[:, None, None] * np.eye(d)


@settings(max_examples=6, deadline=None)
@given(d=st.sampled_from([2, 3]), seed=st.integers(0, 2 ** 32 - 1))
def test_half_storage_is_the_assembled_matrix(d, seed):
    """Upper triangle + diagonal stands for exactly the assembled symmetric matrix: its
    CSR is equal entry for entry, its product agrees to rounding, and its P1 matrix is
    the Galerkin product of the P1 functions (P1 is inside P2)."""
    rng = np.random.default_rng(seed)
    labels = rng.integers(1, 4, (5, 6) if d == 2 else (3, 4, 4)).astype(np.uint8)
    mesh = mesh_labels(labels, spacing=rng.uniform(0.5, 2.0, d))
    material = mesh.material - 1
    space = fe_space(mesh, 2)
    tensors = _tensors(d) * rng.uniform(0.5, 2.0, (3, 1, 1))
    full = stiffness_matrix(space, tensors, material)
    half = p2_stiffness(space, tensors, material)
    assert isinstance(half, P2Stiffness) and half.shape == full.shape
    assert half.nnz == full.nnz
    assert (half.tocsr() != full).nnz == 0
    np.testing.assert_array_equal(half.diagonal(), full.diagonal())
    x = rng.standard_normal((full.shape[0], 2))
    np.testing.assert_allclose(half @ x, full @ x, rtol=0, atol=1e-13 * np.abs(full @ x).max())
    p = p1_embedding(space)
    galerkin = (p.T @ full @ p).toarray()
    np.testing.assert_allclose(half.p1.toarray(), galerkin, rtol=0,
                               atol=1e-12 * np.abs(galerkin).max())
    assert 2 * half.upper.nnz + full.shape[0] == full.nnz        # half of it is stored


def test_p2_stiffness_refuses_a_p1_space():
    mesh = mesh_labels(np.ones((3, 3), np.uint8))
    with pytest.raises(ValueError, match="takes a P2 space, not P1"):
        p2_stiffness(fe_space(mesh, 1), _tensors(2), mesh.material - 1)


def test_lanczos_estimate_with_its_margin_covers_the_spectrum():
    """The Chebyshev range must reach lambda_max of the scaled reduced matrix: the
    estimate lies below it (Ritz values do) and the margin lifts it above."""
    mesh = mesh_labels(blobs((6, 6, 6), seed=2))
    space = fe_space(mesh, 2)
    half = p2_stiffness(space, _tensors(3), mesh.material - 1)
    free = np.ones(space.n_dofs, bool)
    free[np.flatnonzero(space.doflocs[2] <= 1e-9)] = False
    system = TwoLevelDirichlet(half, free, tol=1e-10)
    scaled = sparse.diags(system.scale) @ half.tocsr()[free][:, free] @ sparse.diags(
        system.scale)
    exact = float(eigsh(scaled, k=1, which="LA", tol=1e-12)[0][0])
    estimate = system.interval[1] / LANCZOS_MARGIN
    assert 0.85 * exact < estimate <= exact * (1 + 1e-9)
    assert system.interval[1] >= exact


@pytest.mark.parametrize("d", [2, 3])
def test_two_level_solve_equals_a_direct_solve(d, monkeypatch):
    """Several coarse levels below P1 (a small coarse size forces them), contrast 1e4:
    the solution is the direct one to what the tolerance allows, the fixed values kept."""
    monkeypatch.setattr(_amg, "MAX_COARSE", 20)
    mesh = mesh_labels(blobs((10, 12) if d == 2 else (5, 6, 6), seed=1))
    space = fe_space(mesh, 2)
    tensors = _tensors(d, (1e-2, 1.0, 1e2))
    half = p2_stiffness(space, tensors, mesh.material - 1)
    full = half.tocsr()
    low = np.flatnonzero(space.doflocs[0] <= space.doflocs[0].min() + 1e-9)
    high = np.flatnonzero(space.doflocs[0] >= space.doflocs[0].max() - 1e-9)
    fixed = np.concatenate([low, high])
    values = np.concatenate([np.zeros(low.size), np.ones(high.size)])
    rhs = np.random.default_rng(4).standard_normal(space.n_dofs)
    u, info = DirichletSolver(half, fixed, tol=1e-10).solve(values, rhs)
    free = np.setdiff1d(np.arange(space.n_dofs), fixed)
    direct = spsolve(full[free][:, free].tocsc(),
                     rhs[free] - full[free][:, fixed] @ values)
    assert 1 < info.iterations < 100 and info.residual <= 1e-9
    np.testing.assert_allclose(u[free], direct, rtol=0, atol=1e-6 * np.abs(direct).max())
    np.testing.assert_array_equal(u[fixed], values)


def test_simulate_default_equals_the_assembled_path(monkeypatch):
    """The P2 default (adapted, mixed protocol, three axes) with the half-storage matrix
    gives the k_eff of the assembled matrix and the scikit-fem-checked multigrid, to the
    solver's tolerance."""
    labels = blobs((8, 8, 8), seed=3)
    lean = simulate(labels, K3, interval=False)
    assert lean.order == 2 and lean.choice.startswith("P2")
    monkeypatch.setattr(_simulate, "stiffness_operator",
                        lambda *args, periodic: stiffness_matrix(*args))
    assembled = simulate(labels, K3, interval=False)
    assert assembled.dofs == lean.dofs
    for axis in "xyz":
        assert lean.k_eff[axis] == pytest.approx(assembled.k_eff[axis], rel=1e-9)
        np.testing.assert_allclose(lean.potential[axis], assembled.potential[axis],
                                   rtol=0, atol=1e-7)


def test_budget_counts_half_storage_for_mixed_p2_only():
    """The mixed protocol's P2 is estimated at the half-storage rate, the periodic one
    (assembled in full) and P1 as before."""
    from napari_swa_imesh.simulate import _budget

    mesh = mesh_labels(blobs((6, 6, 6), seed=2))
    n2 = _budget.unknowns(mesh, 2)
    extra = _budget.BYTES_PER_CELL[3] * mesh.n_cells
    half = _budget.estimate_memory(mesh, 2, False)
    full = _budget.estimate_memory(mesh, 2, False, periodic=True)
    assert half == int(_budget.BYTES_PER_UNKNOWN_HALF[3] * n2 + _budget.BYTES_HALF_FIXED
                       + extra)
    assert full == int(_budget.BYTES_PER_UNKNOWN[(3, 2)] * n2 + extra)
    big = 10 ** 7                                 # the fixed part is small at real sizes
    assert _budget.BYTES_PER_UNKNOWN_HALF[3] * big + _budget.BYTES_HALF_FIXED < (
        _budget.BYTES_PER_UNKNOWN[(3, 2)] * big)
    assert (_budget.estimate_memory(mesh, 1, False)
            == _budget.estimate_memory(mesh, 1, False, periodic=True))
