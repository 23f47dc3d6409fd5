"""The symmetric CSR layout of the assembly against scipy's own COO sums.

:mod:`._sparse` adds the batches of upper-triangle entries pairwise and lays out
``U + U^T + diag`` by index arithmetic; the reference here is scipy's COO conversion and
sparse addition of the same entries (what the assembly did before), and a plain
element-by-element COO assembly of the whole (both triangles) stiffness matrix.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse

from napari_swa_imesh.mesh import Mesh, mesh_labels
from napari_swa_imesh.simulate import _assembly
from napari_swa_imesh.simulate._assembly import _pair_table, fe_space, stiffness_matrix
from napari_swa_imesh.simulate._solve import connected_parts, element_parts
from napari_swa_imesh.simulate._sparse import sum_pairwise, symmetric_from_upper


def _canonical(m: sparse.csr_matrix) -> bool:
    """Sorted, no duplicates, no stored zeros: checked on the arrays, not the flags."""
    rows = np.repeat(np.arange(m.shape[0]), np.diff(m.indptr))
    keys = rows.astype(np.int64) * m.shape[1] + m.indices
    return bool(np.all(np.diff(keys) > 0) and np.all(m.data != 0))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 30), m=st.integers(0, 200), pieces=st.integers(1, 7),
       seed=st.integers(0, 2 ** 32 - 1))
def test_pairwise_sum_and_mirror_equal_scipy(n, m, pieces, seed):
    """Random strict-upper entries with many duplicates and some that cancel exactly:
    the pairwise sum of the pieces and the laid-out symmetric matrix equal scipy's sums,
    canonical and exactly symmetric."""
    rng = np.random.default_rng(seed)
    i, j = rng.integers(0, n, (2, m))
    keep = i != j
    rows, cols = np.minimum(i, j)[keep], np.maximum(i, j)[keep]
    data = rng.choice([-2.0, -1.0, 0.5, 1.0, 2.0], rows.size)   # sums often cancel to 0
    cuts = np.sort(rng.integers(0, rows.size + 1, pieces - 1))
    parts = [sparse.csr_matrix((d, (r, c)), shape=(n, n)) for r, c, d in
             zip(np.split(rows, cuts), np.split(cols, cuts), np.split(data, cuts))]
    upper = sum_pairwise(parts)
    reference = sparse.csr_matrix((data, (rows, cols)), shape=(n, n))
    assert _canonical(upper)
    np.testing.assert_array_equal(upper.toarray(), reference.toarray())
    diagonal = rng.uniform(1.0, 2.0, n)
    full = symmetric_from_upper(upper, diagonal)
    assert _canonical(full)
    expected = (reference + reference.T + sparse.diags(diagonal)).toarray()
    np.testing.assert_array_equal(full.toarray(), expected)
    assert (full != full.T).nnz == 0


def _coo_stiffness(space, tensors, cell_material) -> sparse.csr_matrix:
    """The plain reference: every element's full matrix (both triangles) as COO entries,
    one conversion; entries from the same pair table, so only the assembly differs."""
    a, b, table = _pair_table(space.ndim, space.order)
    products = _assembly._gradient_products(space, slice(0, len(space.cells)), tensors,
                                            cell_material)
    values = products if space.order == 1 else table @ products         # (K, M)
    dofs = space.element_dofs.T
    off = a != b
    rows = np.concatenate([dofs[a].ravel(), dofs[b[off]].ravel()])
    cols = np.concatenate([dofs[b].ravel(), dofs[a[off]].ravel()])
    data = np.concatenate([values.ravel(), values[off].ravel()])
    return sparse.csr_matrix((data, (rows, cols)), shape=(space.n_dofs,) * 2)


@pytest.mark.parametrize("shape", [(6, 5), (4, 3, 5)])
@pytest.mark.parametrize("order", [1, 2])
def test_batched_assembly_equals_one_coo_assembly(shape, order, monkeypatch):
    """Tiny chunks and batches (dozens of pieces for the pairwise sum, on two threads)
    give the plain COO assembly's matrix to 1e-12, canonical and exactly symmetric
    (random small meshes, their vertices moved, random tensors)."""
    rng = np.random.default_rng(sum(shape) + order)
    labels = rng.integers(1, 4, shape).astype(np.uint8)
    mesh = mesh_labels(labels, spacing=rng.uniform(0.5, 2.0, len(shape)))
    mesh = Mesh(points=mesh.points + rng.uniform(-0.05, 0.05, mesh.points.shape),
                cells=mesh.cells, material=mesh.material)
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    a = rng.standard_normal((3, mesh.ndim, mesh.ndim))
    tensors = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(mesh.ndim)
    space = fe_space(mesh, order)
    reference = _coo_stiffness(space, tensors, cell_material)
    monkeypatch.setattr(_assembly, "CHUNK", 5)
    monkeypatch.setattr(_assembly, "BATCH", 40)
    ours = stiffness_matrix(space, tensors, cell_material)
    assert _canonical(ours)
    assert (ours != ours.T).nnz == 0
    assert abs(ours - reference).max() <= 1e-12 * abs(reference).max()
    # the only entries dropped are the exact zeros (P2 has structural ones: a vertex and
    # the midpoint of the opposite edge of a triangle do not couple)
    reference.eliminate_zeros()
    assert ours.nnz == reference.nnz


@pytest.mark.parametrize("shape", [(9, 8), (6, 5, 7)])
@pytest.mark.parametrize("order", [1, 2])
def test_element_parts_are_the_matrix_parts(shape, order):
    """Random labels with one material excluded leave many separate parts (islands,
    corners touching): the parts from the element stars are those of the matrix."""
    rng = np.random.default_rng(sum(shape) * order)
    labels = np.where(rng.random(shape) < 0.1, rng.integers(2, 4, shape), 1).astype(np.uint8)
    mesh = mesh_labels(labels, exclude=[1])
    _, cell_material = np.unique(mesh.material, return_inverse=True)
    space = fe_space(mesh, order)
    matrix = stiffness_matrix(space, np.stack([np.eye(mesh.ndim)] * 2), cell_material)
    expected = connected_parts(matrix)
    parts = element_parts(mesh.cells, len(mesh.points), space.edges)
    assert parts.shape == expected.shape
    assert np.unique(expected).size > 2                  # the case is not trivial
    # the same partition: each label of one maps to exactly one label of the other
    pairs = np.unique(np.stack([parts, expected]), axis=1)
    assert pairs.shape[1] == np.unique(parts).size == np.unique(expected).size


@pytest.mark.parametrize("count", [1, 2, 3, 5, 7, 12, 29])
@pytest.mark.parametrize("blocks", [1, 3, 16])
def test_pairwise_sum_in_row_blocks_is_sum_pairwise_bit_for_bit(count, blocks):
    """Batches summed as they come, in row blocks, give sum_pairwise's matrix exactly:
    the same tree of additions (so the same floating-point sums), entries that cancel
    dropped, canonical."""
    from napari_swa_imesh.simulate._sparse import PairwiseSum

    rng = np.random.default_rng(count * 100 + blocks)
    n = 150
    parts = []
    for _ in range(count):
        r, c = rng.integers(0, n, 400), rng.integers(0, n, 400)
        v = rng.standard_normal(400)
        v[:4] = 0.0
        parts.append(sparse.csr_matrix((v, (r, c)), shape=(n, n)))
    parts.append(-parts[0])                               # cancels the first exactly
    total = PairwiseSum((n, n), blocks)
    for p in parts:
        total.add(p.copy())
        total.merge()
    got = total.result()
    want = sum_pairwise([p.copy() for p in parts])
    assert got.has_canonical_format and got.shape == want.shape
    np.testing.assert_array_equal(got.indptr, want.indptr)
    np.testing.assert_array_equal(got.indices, want.indices)
    np.testing.assert_array_equal(got.data.view(np.int64), want.data.view(np.int64))
    assert not np.any(got.data == 0)
