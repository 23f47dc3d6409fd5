"""Our vectorised assembly and multigrid against independent references.

scikit-fem assembles the same forms its own way (shape functions at quadrature points,
COO lists); scipy's sparse LU solves the same systems directly.
"""

import numpy as np
import pytest
import skfem
from scipy import sparse
from scipy.sparse.linalg import spsolve
from skfem.helpers import dot, grad, mul

from napari_swa_imesh.mesh import Mesh, mesh_labels, signed_volumes
from napari_swa_imesh.simulate import _assembly
from napari_swa_imesh.simulate._assembly import (
    cell_fluxes,
    cell_gradients,
    cell_volumes,
    dissipation,
    fe_space,
    p1_embedding,
    stiffness_matrix,
)
from napari_swa_imesh.simulate._fe import fe_basis
from napari_swa_imesh.simulate._periodic import PeriodicProblem
from napari_swa_imesh.simulate._solve import DirichletSolver, SPDSolver, solve_dirichlet


def _skfem_stiffness(basis, tensors, cell_material):
    """The reference: scikit-fem's own assembly of ``(C grad u) . grad v``."""
    nqp = basis.X.shape[-1]
    per_cell = np.moveaxis(tensors[cell_material], 0, -1)                 # (d, d, M)
    field = np.broadcast_to(per_cell[..., None], per_cell.shape + (nqp,))

    @skfem.BilinearForm
    def form(u, v, w):
        return dot(mul(w["c"], grad(u)), grad(v))
    return skfem.asm(form, basis, c=np.ascontiguousarray(field)).tocsr()


def _random_mesh(rng, shape, jitter: bool) -> Mesh:
    """An IMESH mesh of random labels with a random spacing; with `jitter`, every vertex
    moved a little, so no two elements share a shape (no right angles left)."""
    labels = rng.integers(1, 4, shape).astype(np.uint8)
    mesh = mesh_labels(labels, spacing=rng.uniform(0.5, 2.0, len(shape)))
    if jitter:
        points = mesh.points + rng.uniform(-0.08, 0.08, mesh.points.shape)
        mesh = Mesh(points=points, cells=mesh.cells, material=mesh.material,
                    material_names=mesh.material_names)
    return mesh


def _random_tensors(rng, d: int, n: int = 3) -> np.ndarray:
    """n symmetric positive definite tensors spanning three decades."""
    a = rng.standard_normal((n, d, d))
    return (a @ a.transpose(0, 2, 1) + 0.1 * np.eye(d)) * 10.0 ** rng.uniform(-1, 2, (n, 1, 1))


@pytest.mark.parametrize("shape", [(5, 7), (4, 5, 6)])
@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("jitter", [False, True])
def test_stiffness_equals_scikit_fem(shape, order, jitter, monkeypatch):
    """Same matrix to 1e-12 relative, same numbering, on random meshes and tensors; the
    chunks and batches are made tiny so that their seams are crossed many times."""
    monkeypatch.setattr(_assembly, "CHUNK", 7)
    monkeypatch.setattr(_assembly, "BATCH", 50)
    rng = np.random.default_rng(len(shape) * 10 + order + 2 * jitter)
    mesh = _random_mesh(rng, shape, jitter)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = _random_tensors(rng, mesh.ndim)
    basis = fe_basis(mesh, order)
    space = fe_space(mesh, order)
    reference = _skfem_stiffness(basis, tensors, cell_material)
    volumes = np.full(mesh.n_cells, np.nan)
    ours = stiffness_matrix(space, tensors, cell_material, volumes)
    np.testing.assert_allclose(volumes, signed_volumes(mesh.points, mesh.cells), rtol=1e-12)
    assert ours.shape == reference.shape == (space.n_dofs,) * 2
    assert abs(ours - reference).max() <= 1e-12 * abs(reference).max()
    assert abs(ours - ours.T).max() == 0.0                   # mirrored, not recomputed
    np.testing.assert_allclose(space.doflocs, basis.doflocs, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.sort(space.element_dofs, axis=1),
                                  np.sort(basis.element_dofs.T, axis=1))


@pytest.mark.parametrize("shape", [(5, 7), (4, 5, 6)])
@pytest.mark.parametrize("order", [1, 2])
def test_energy_and_gradients_equal_scikit_fem(shape, order, monkeypatch):
    """The dissipated energy equals u.K.u and scikit-fem's integral; the element
    gradients equal the mean of scikit-fem's gradient over the element."""
    monkeypatch.setattr(_assembly, "CHUNK", 11)
    rng = np.random.default_rng(7 + order)
    mesh = _random_mesh(rng, shape, jitter=True)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = _random_tensors(rng, mesh.ndim)
    space = fe_space(mesh, order)
    u = rng.standard_normal(space.n_dofs)
    energy = dissipation(space, u, tensors, cell_material)
    matrix = stiffness_matrix(space, tensors, cell_material)
    assert energy == pytest.approx(float(u @ (matrix @ u)), rel=1e-12)

    exact = skfem.Basis(fe_basis(mesh, order).mesh, fe_basis(mesh, order).elem,
                        intorder=2 * order + 1)
    g = exact.interpolate(u).grad                                    # (d, M, nqp)
    per_cell = np.moveaxis(tensors[cell_material], 0, -1)[..., None]  # (d, d, M, 1)
    density = np.einsum("imq,ijmq,jmq->mq", g, per_cell, g)
    assert energy == pytest.approx(float(np.sum(density * exact.dx)), rel=1e-12)
    mean = (np.einsum("imq,mq->mi", g, exact.dx) / exact.dx.sum(axis=1)[:, None])
    np.testing.assert_allclose(cell_gradients(space, u), mean, rtol=0,
                               atol=1e-10 * np.abs(mean).max())
    # the one-pass flux and energy: -C times the mean gradient, the same energy
    flux, energy_again = cell_fluxes(space, u, tensors, cell_material)
    expected = -np.einsum("mij,mj->mi", tensors[cell_material], mean)
    np.testing.assert_allclose(flux, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    assert energy_again == pytest.approx(energy, rel=1e-12)
    np.testing.assert_allclose(cell_volumes(space), signed_volumes(mesh.points, mesh.cells),
                               rtol=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_multigrid_solve_equals_a_direct_solve(order, monkeypatch):
    """Several multigrid levels (a small coarse size forces them) and conjugate gradients
    reach the direct solution to the asked tolerance, contrast 1e4 included."""
    from napari_swa_imesh.simulate import _amg

    monkeypatch.setattr(_amg, "MAX_COARSE", 20)
    rng = np.random.default_rng(3)
    mesh = _random_mesh(rng, (5, 6, 7) if order == 1 else (3, 4, 5), jitter=False)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = np.array([1e-2, 1.0, 1e2])[:, None, None] * np.eye(3)
    space = fe_space(mesh, order)
    matrix = stiffness_matrix(space, tensors, cell_material)
    fixed = np.flatnonzero(space.doflocs[2] <= space.doflocs[2].min() + 1e-9)
    rhs = rng.standard_normal(space.n_dofs)
    u, info = solve_dirichlet(matrix, fixed, np.zeros(fixed.size), rhs, tol=1e-10)
    free = np.setdiff1d(np.arange(space.n_dofs), fixed)
    direct = spsolve(matrix[free][:, free].tocsc(), rhs[free])
    assert 1 < info.iterations < 100
    assert info.setup > 0 and info.seconds >= info.setup
    # the residual is 1e-10; the error, that times a condition number near 1e4
    np.testing.assert_allclose(u[free], direct, rtol=0, atol=1e-6 * np.abs(direct).max())
    assert np.all(u[fixed] == 0.0)


def test_spd_solver_leaves_its_matrix_alone_unless_told():
    """The diagonal scaling works on a copy by default, in place with overwrite=True."""
    matrix = sparse.diags([-np.ones(9), 4 * np.ones(10), -np.ones(9)], [-1, 0, 1],
                          format="csr")
    before = matrix.toarray()
    x, _ = SPDSolver(matrix).solve(np.ones(10))
    np.testing.assert_array_equal(matrix.toarray(), before)
    np.testing.assert_allclose(matrix @ x, np.ones(10), atol=1e-9)
    SPDSolver(matrix, overwrite=True)
    np.testing.assert_allclose(matrix.diagonal(), 1.0)


def test_periodic_problem_builds_one_hierarchy_for_every_axis(monkeypatch):
    """The folded matrix is the same for every mean gradient: one set-up, reported with
    the first solve; the later solves report none and build nothing."""
    from napari_swa_imesh.simulate import _solve

    built = []
    original = _solve.SPDSolver.__init__

    def counting(self, *args, **kwargs):
        built.append(1)
        original(self, *args, **kwargs)

    monkeypatch.setattr(_solve.SPDSolver, "__init__", counting)
    labels = np.random.default_rng(5).integers(1, 3, (5, 6, 7)).astype(np.uint8)
    mesh = mesh_labels(labels, periodic=True)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    space = fe_space(mesh, 1)
    matrix = stiffness_matrix(space, np.array([1.0, 5.0])[:, None, None] * np.eye(3),
                              cell_material)
    lo, hi = mesh.image_box()
    problem = PeriodicProblem(matrix, space.doflocs, lo, hi, tol=1e-10)
    infos = [problem.solve(axis)[2] for axis in range(3)]
    assert len(built) == 1
    assert infos[0].setup > 0
    assert [i.setup for i in infos[1:]] == [0.0, 0.0]
    assert all(i.residual <= 1e-9 for i in infos)


def test_p2_multigrid_starts_from_the_p1_functions(monkeypatch):
    """P2: the first coarse level is the P1 space on the free vertices (its Galerkin
    matrix is the P1 stiffness there), and the solve still equals a direct one."""
    from napari_swa_imesh.simulate import _amg

    monkeypatch.setattr(_amg, "MAX_COARSE", 20)
    rng = np.random.default_rng(11)
    mesh = _random_mesh(rng, (3, 4, 5), jitter=True)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    tensors = _random_tensors(rng, 3)
    space = fe_space(mesh, 2)
    matrix = stiffness_matrix(space, tensors, cell_material)
    embedding = p1_embedding(space)
    assert embedding.shape == (space.n_dofs, len(mesh.points))
    # a P1 function is reproduced exactly: x + 2y - z at every P2 dof
    linear = mesh.points @ np.array([1.0, 2.0, -1.0])
    np.testing.assert_allclose(embedding @ linear,
                               space.doflocs.T @ np.array([1.0, 2.0, -1.0]), atol=1e-12)
    fixed = np.flatnonzero(space.doflocs[0] <= space.doflocs[0].min() + 1e-9)
    problem = DirichletSolver(matrix, fixed, tol=1e-10, coarse=embedding)
    free_vertices = np.setdiff1d(np.arange(len(mesh.points)), fixed)
    assert problem.solver.hierarchy.sizes[:2] == [space.n_dofs - fixed.size,
                                                  free_vertices.size]
    p1 = stiffness_matrix(fe_space(mesh, 1), tensors, cell_material)
    assert len(problem.solver.hierarchy.matrices) > 2        # aggregation below P1
    galerkin = problem.solver.hierarchy.matrices[1]           # float32: P1's free block
    expected = p1[free_vertices][:, free_vertices]
    assert abs(galerkin - expected).max() <= 1e-5 * abs(expected).max()
    rhs = rng.standard_normal(space.n_dofs)
    u, info = problem.solve(np.zeros(fixed.size), rhs)
    free = np.setdiff1d(np.arange(space.n_dofs), fixed)
    direct = spsolve(matrix[free][:, free].tocsc(), rhs[free])
    np.testing.assert_allclose(u[free], direct, rtol=0, atol=1e-6 * np.abs(direct).max())


def test_multigrid_bottom_level_and_unconnected_unknowns(monkeypatch):
    """Unknowns that aggregation cannot group (a diagonal matrix, pieces of two) are
    solved exactly; a bottom level above MAX_DENSE is factorised by a sparse LU."""
    from napari_swa_imesh.simulate import _amg

    rng = np.random.default_rng(2)
    diagonal = sparse.diags(rng.uniform(1.0, 10.0, 3000), format="csr")
    x, _ = SPDSolver(diagonal, tol=1e-12).solve(np.ones(3000))
    np.testing.assert_allclose(x, 1.0 / diagonal.diagonal(), rtol=1e-10)
    pairs = sparse.block_diag([np.array([[2.0, -1.0], [-1.0, 2.0]])] * 1500, format="csr")
    x, _ = SPDSolver(pairs, tol=1e-12).solve(np.ones(3000))
    np.testing.assert_allclose(x, 1.0, rtol=1e-10)

    factorised = []
    original = _amg._coarse_solver

    def spy(a):
        factorised.append(a.shape[0] > _amg.MAX_DENSE)
        return original(a)

    monkeypatch.setattr(_amg, "MAX_DENSE", 10)
    monkeypatch.setattr(_amg, "_coarse_solver", spy)
    mesh = _random_mesh(rng, (6, 7, 8), jitter=False)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    space = fe_space(mesh, 1)
    matrix = stiffness_matrix(space, np.array([1.0, 3.0, 9.0])[:, None, None] * np.eye(3),
                              cell_material)
    fixed = np.flatnonzero(space.doflocs[1] <= space.doflocs[1].min() + 1e-9)
    rhs = rng.standard_normal(space.n_dofs)
    u, _ = solve_dirichlet(matrix, fixed, np.zeros(fixed.size), rhs, tol=1e-11)
    assert factorised == [True]
    free = np.setdiff1d(np.arange(space.n_dofs), fixed)
    direct = spsolve(matrix[free][:, free].tocsc(), rhs[free])
    np.testing.assert_allclose(u[free], direct, rtol=0, atol=1e-7 * np.abs(direct).max())
