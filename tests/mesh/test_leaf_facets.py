"""The leaf-by-leaf path to the facet groups of a template mesh gives exactly the groups
of the general path (every facet occurrence paired by a sort), and steps aside for
meshes it cannot vouch for."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_swa_imesh.mesh import Mesh, facet_groups, mesh_labels
from napari_swa_imesh.mesh.checks._facets import _sorted_groups
from napari_swa_imesh.mesh.checks._leaf_facets import (
    _as_made,
    material_codes,
    present_materials,
    template_group_rows,
)


def _assert_same(fast, slow):
    assert list(fast) == list(slow)                          # names, in order
    for name in slow:
        for field in ("facets", "owner", "opposite"):
            assert np.array_equal(getattr(fast[name], field), getattr(slow[name], field)), \
                (name, field)


@st.composite
def _cases(draw):
    d = draw(st.sampled_from([2, 3]))
    shape = tuple(draw(st.lists(st.integers(1, 9 if d == 3 else 20), min_size=d, max_size=d)))
    seed = draw(st.integers(0, 2**31))
    blocky = draw(st.booleans())
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, draw(st.integers(1, 4)), size=shape)
    if blocky:       # big leaves as well as voxel ones
        labels = np.kron(labels, np.ones((2,) * d, int))[tuple(slice(0, n) for n in shape)]
    options = draw(st.sampled_from([{}, {"exclude": [0]}, {"refine": 1},
                                    {"spacing": (2.5,) + (1.0,) * (d - 1)},
                                    {"periodic": True}, {"max_size": 3.0}]))
    return labels, options


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_cases())
def test_leaf_path_gives_the_groups_of_the_sorting_path(case):
    labels, options = case
    try:
        mesh = mesh_labels(labels, **options)
    except ValueError:          # everything excluded, or a size cap below the lattice
        return
    assert template_group_rows(mesh) is not None             # the fast path was taken
    expected = _sorted_groups(mesh)
    assert mesh.made is not None and _as_made(mesh) is mesh.made     # the mesher's record
    _assert_same(facet_groups(mesh), expected)
    mesh.made = None                                         # and from the points alone
    _assert_same(facet_groups(mesh), expected)


def test_meshes_not_from_the_template_mesher_take_the_sorting_path():
    labels = np.random.default_rng(3).integers(1, 3, (6, 5, 4))
    mesh = mesh_labels(labels)
    cut = Mesh(mesh.points, mesh.cells[::2], mesh.material[::2],
               {k: v[::2] for k, v in mesh.cell_data.items()}, spacing=mesh.spacing,
               shape=mesh.shape, info=mesh.info)               # half the elements gone
    assert template_group_rows(cut) is None
    _assert_same(facet_groups(cut), _sorted_groups(cut))
    delaunay = mesh_labels(labels[..., 0], method="delaunay")
    assert template_group_rows(delaunay) is None


def test_material_codes_rank_large_ids_too():
    materials, code = material_codes(np.array([5, 2**40, 5, 0]))
    assert materials.tolist() == [0, 5, 2**40]
    assert code.tolist() == [1, 2, 1, 0]
    materials, code = material_codes(np.array([3, 3, 1], np.uint8))
    assert materials.tolist() == [1, 3] and code.tolist() == [1, 1, 0]
    assert materials.dtype == np.uint8 and code.dtype == np.int16


@pytest.mark.parametrize("values", [[5, 2**40, 5, 0], [3, 3, 1], [-4, 7, -4], [2**20 + 3, 1]])
def test_present_materials_are_the_materials_of_material_codes(values):
    for dtype in (np.int64, np.uint8) if max(values) < 256 and min(values) >= 0 else (np.int64,):
        material = np.array(values, dtype=dtype)
        present = present_materials(material)
        np.testing.assert_array_equal(present, np.unique(material))
        assert present.dtype == material.dtype
        np.testing.assert_array_equal(present, material_codes(material)[0])


@pytest.mark.parametrize("world", [None, np.diag([-2.0, 1.0, 0.5, 1.0]), np.diag([2.0, 1, 1, 1]),
                                   np.array([[0.0, 1, 0, 3], [1, 0, 0, -1], [0, 0, 2, 0],
                                             [0, 0, 0, 1]])])
def test_orientation_from_the_leaf_path_is_the_computed_one(world):
    from napari_swa_imesh.mesh.formats._prepare import ExportMesh

    labels = np.random.default_rng(5).integers(0, 3, (6, 7, 5))
    mesh = mesh_labels(labels, exclude=[0], spacing=(2.5, 1.0, 1.0))
    mesh.world = world
    leaf, computed = ExportMesh(mesh), ExportMesh(mesh, groups="none")
    assert np.array_equal(leaf.flip, computed.flip)
    turns = world is None or np.linalg.det(world[:3, :3]) < 0   # the mesher's cells are positive
    assert leaf.flip.all() if turns else not leaf.flip.any()


@pytest.mark.parametrize("big_leaf", [1, 64])
def test_big_leaves_painted_one_by_one_give_the_same_groups(monkeypatch, big_leaf):
    from napari_swa_imesh.mesh.checks import _leaf_facets

    labels = np.zeros((40, 36, 30), np.uint8)                  # leaves up to 16^3
    labels[10:17, 20:23, 5:12] = 1
    labels[30, 3, 25] = 2
    mesh = mesh_labels(labels)
    expected = _sorted_groups(mesh)
    monkeypatch.setattr(_leaf_facets, "_BIG_LEAF", big_leaf)
    assert template_group_rows(mesh) is not None
    _assert_same(facet_groups(mesh), expected)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("longest", [1, 1 << 9, (1 << 9) + 1, 1 << 20])
def test_lattice_det_is_exact_in_int32_and_int64(d, longest):
    """The orientation determinant of lattice corners, in int32 for short edges (no
    casts) and int64 beyond, equals the exact integer one; edges of exactly 2**9,
    all of one sign, are the int32 worst case."""
    from napari_swa_imesh.mesh.checks._leaf_facets import _lattice_det

    rng = np.random.default_rng(longest)
    base = rng.integers(1 << 21, 1 << 22, (500, 1, d))
    edges = rng.integers(-longest, longest + 1, (500, d, d))
    edges[:4] = longest * np.array([1, -1, 1, -1])[:, None, None] * np.ones((d, d), int)
    edges[4:8] = longest * (2 * (rng.random((4, d, d)) < 0.5) - 1)
    edges[8] = longest * np.array([[1, 1, -1], [1, -1, 1], [-1, 1, 1]])[:d, :d]
    corners = np.concatenate([base, base + edges], axis=1).astype(np.int32)  # (n, d+1, d)
    p = [[np.ascontiguousarray(corners[:, k, a]) for a in range(d)] for k in range(d + 1)]
    e = edges.astype(object)                                    # Python integers
    exact = (e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0] if d == 2 else
             e[:, 0, 0] * (e[:, 1, 1] * e[:, 2, 2] - e[:, 1, 2] * e[:, 2, 1])
             + e[:, 0, 1] * (e[:, 1, 2] * e[:, 2, 0] - e[:, 1, 0] * e[:, 2, 2])
             + e[:, 0, 2] * (e[:, 1, 0] * e[:, 2, 1] - e[:, 1, 1] * e[:, 2, 0]))
    got = _lattice_det(p)
    assert got.tolist() == exact.tolist()
    assert got.dtype == (np.int32 if longest <= 1 << 9 else np.int64)


def _flips_as_computed(mesh):
    from napari_swa_imesh.mesh.formats._prepare import ExportMesh

    leaf, computed = ExportMesh(mesh), ExportMesh(mesh, groups="none")
    assert np.array_equal(leaf.flip, computed.flip)
    return leaf.flip


def test_an_unchanged_template_mesh_skips_the_sign_pass(monkeypatch):
    from napari_swa_imesh.mesh.checks import _leaf_facets

    labels = np.random.default_rng(8).integers(0, 3, (9, 8, 7))
    mesh = mesh_labels(labels)
    expected = _flips_as_computed(mesh)

    def no_sign_pass(p):
        raise AssertionError("the signs of an unchanged template mesh are known")

    monkeypatch.setattr(_leaf_facets, "_lattice_det", no_sign_pass)
    assert np.array_equal(_flips_as_computed(mesh), expected)


@pytest.mark.parametrize("change", ["swap corners", "swap point axes", "mirror an axis"])
def test_a_template_mesh_changed_after_meshing_gets_its_signs_computed(change):
    """The mesher's arrays are read-only; a mesh given changed arrays has no record, so
    its facets are paired by the sort and its signs computed."""
    labels = np.random.default_rng(9).integers(0, 3, (7, 8, 8))   # axes 1 and 2 alike
    mesh = mesh_labels(labels)
    before = _flips_as_computed(mesh).copy()
    some = np.arange(0, mesh.n_cells, 7)
    with pytest.raises(ValueError, match="read-only"):
        mesh.cells[some, 0] = 0
    with pytest.raises(ValueError, match="read-only"):
        mesh.points[:, 0] *= -1
    if change == "swap corners":      # same counts, same leaves: only the signs differ
        cells = mesh.cells.copy()
        cells[some, 0], cells[some, 1] = cells[some, 1], cells[some, 0].copy()
        mesh.cells = cells
    elif change == "swap point axes":  # a cube's lattice still: every element turned
        mesh.points = mesh.points[:, [0, 2, 1]]
    else:                              # only sign bits change, an even number of them
        assert len(mesh.points) % 2 == 0
        mesh.points = mesh.points * [-1, 1, 1]
    assert mesh.recipe is None and mesh.made is None
    assert template_group_rows(mesh) is None
    after = _flips_as_computed(mesh)
    turned = np.zeros(mesh.n_cells, bool)
    turned[some if change == "swap corners" else slice(None)] = True
    np.testing.assert_array_equal(after, before ^ turned)


def test_a_changed_leaf_array_is_not_taken_from_the_mesher_s_record():
    labels = np.zeros((8, 8, 8), np.uint8)
    labels[2:6, 1:7, 3:5] = 1
    mesh = mesh_labels(labels)
    expected = _sorted_groups(mesh)
    leaf = mesh.cell_data["leaf"]
    # the same partition of the elements under other leaf ids: the groups cannot change,
    # but the record's origins (by leaf id) no longer apply
    mesh.cell_data["leaf"] = leaf.max() - leaf
    assert _as_made(mesh) is None
    _assert_same(facet_groups(mesh), expected)
