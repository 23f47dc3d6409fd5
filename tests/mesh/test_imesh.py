"""Property tests of mesh_labels over many seeded label images, and its errors."""

import math

import numpy as np
import pytest
from imesh_cases import blobs, cases, noise

from napari_swa_imesh import build_tree
from napari_swa_imesh.mesh.checks._checks import check_mesh, rasterize_materials
from napari_swa_imesh.mesh.mesher._imesh import mesh_labels, mesh_tree
from napari_swa_imesh.mesh.model._quality import dihedral_angles, radius_edge_ratio, triangle_angles

BOUND = {2: 1 / math.sqrt(2), 3: math.sqrt(5) / 2}
CASES = [(d, name, lab) for d in (2, 3) for name, lab in cases(d)]


@pytest.mark.parametrize("d,name,lab", CASES, ids=[f"{d}d-{n}" for d, n, _ in CASES])
@pytest.mark.parametrize("exclude", [(), (0,)])
def test_template_mesh_passes_every_check(d, name, lab, exclude):
    if set(np.unique(lab).tolist()) <= set(exclude):
        pytest.skip("everything excluded")
    before = lab.copy()
    mesh = mesh_labels(lab, exclude=exclude)
    np.testing.assert_array_equal(lab, before)
    checks = check_mesh(mesh, lab, exclude=exclude)
    assert checks["all_passed"], checks
    assert mesh.points.dtype == np.float64 and mesh.cells.shape[1] == d + 1
    assert mesh.info["worst_ratio"] <= BOUND[d] + 1e-12
    assert not np.isin(mesh.material, exclude).any()
    # every point is used by an element (no orphan vertex for an FE solver)
    assert np.array_equal(np.unique(mesh.cells), np.arange(len(mesh.points)))
    # per-element quality from the template table equals direct computation
    np.testing.assert_allclose(mesh.quality, radius_edge_ratio(mesh.points, mesh.cells), rtol=1e-9)
    if d == 2:
        lo, hi = triangle_angles(mesh.points, mesh.cells)
        np.testing.assert_allclose(mesh.cell_data["min_angle"], lo, rtol=1e-9)
        assert lo.min() >= 45 - 1e-9 and hi.max() <= 90 + 1e-9
    else:
        lo, hi = dihedral_angles(mesh.points, mesh.cells)
        np.testing.assert_allclose(mesh.cell_data["min_dihedral"], lo, rtol=1e-9)
        np.testing.assert_allclose(mesh.cell_data["max_dihedral"], hi, rtol=1e-9)
        assert lo.min() >= 35.26 and hi.max() <= 125.27
    # level and leaf per element are consistent with element size
    assert mesh.cell_data["level"].shape == mesh.cell_data["leaf"].shape == (mesh.n_cells,)


@pytest.mark.parametrize("spacing", [0.5, (2.0, 0.25)])
def test_spacing_places_points_in_physical_units(spacing):
    lab = blobs((20, 24), 3, seed=4)
    plain = mesh_labels(lab)
    # without subdivision the lattice is the voxels: the same mesh, scaled
    scaled = mesh_labels(lab, spacing=spacing, subdivide=False)
    np.testing.assert_allclose(scaled.points, plain.points * np.broadcast_to(spacing, (2,)))
    np.testing.assert_array_equal(scaled.cells, plain.cells)
    assert scaled.points.max(axis=0) == pytest.approx(
        np.array(lab.shape) * np.broadcast_to(spacing, (2,)))
    assert check_mesh(scaled, lab)["all_passed"]
    np.testing.assert_allclose(scaled.quality, radius_edge_ratio(scaled.points, scaled.cells),
                               rtol=1e-9)


def test_coarse_inside_fine_at_boundaries():
    lab = np.zeros((64, 64), np.int64)
    lab[20:41, 10:50] = 1
    mesh = mesh_labels(lab)
    assert mesh.n_cells < 0.15 * 2 * lab.size  # vs two triangles per pixel
    level = mesh.cell_data["level"]
    assert level.max() >= 3 and level.min() == 0
    np.testing.assert_array_equal(rasterize_materials(mesh), lab)


def test_info_counts():
    lab = noise((16, 16, 16), 3, seed=1, p=0.02)
    mesh = mesh_labels(lab, material_names={1: "bone"})
    info = mesh.info
    assert info["n_elements"] == mesh.n_cells and info["n_vertices"] == len(mesh.points)
    assert mesh.recipe.balance == "faces+edges"
    # the face-balance count needs a second balance pass: only on request
    assert info["n_leaves_face_balanced"] is None and info["balance_element_cost"] is None
    assert "face_balance_count" not in info["seconds"]
    full = mesh_tree(build_tree(lab), report_face_balance=True).info
    assert info["n_leaves_tree"] <= full["n_leaves_face_balanced"] <= info["n_leaves_balanced"]
    assert (full["balance_extra_leaves"]
            == info["n_leaves_balanced"] - full["n_leaves_face_balanced"])
    assert mesh_labels(lab[0]).info["n_leaves_face_balanced"] == mesh_labels(lab[0]).info[
        "n_leaves_balanced"]  # 2-D: the balance used is the face balance
    assert info["worst_ratio"] == pytest.approx(mesh.quality.max())
    assert {"tree", "balance", "vertices", "simplices", "quality"} <= set(info["seconds"])
    assert mesh.material_names == {1: "bone"}
    assert len(np.unique(mesh.cells, axis=0)) == mesh.n_cells


def test_delaunay_2d_matches_the_reference():
    lab = blobs((32, 32), 3, seed=2)
    mesh = mesh_labels(lab, method="delaunay")
    assert mesh.info["n_zero_volume"] == 0
    assert mesh.info["worst_ratio"] <= math.sqrt(5) / 2 + 1e-9
    assert check_mesh(mesh, lab)["conforming"]


def test_delaunay_3d_is_reported_honestly():
    lab = noise((16, 16, 16), 3, seed=3, p=0.05)
    mesh = mesh_labels(lab, method="delaunay")
    info = mesh.info
    assert info["n_zero_volume"] > 0  # co-spherical cube corners: Qhull's flat slivers
    assert info["conforming"] is False
    assert info["checks"]["conforming"] is False
    assert check_mesh(mesh, lab)["positive_volume"]  # dropped, not kept


@pytest.mark.parametrize("labels,kwargs,error,match", [
    (np.array([[0.5, 1.0], [1.0, 2.0]]), {}, ValueError, "non-integer"),
    (np.zeros((0, 4)), {}, ValueError, "empty"),
    (np.zeros(8, int), {}, ValueError, "2-D to 3-D; got 1-D"),
    (np.zeros((2,) * 5, int), {}, ValueError, "2-D to 3-D; got 5-D"),
    (np.array([[1, -1], [0, 1]]), {}, ValueError, "negative"),
    (np.array([["a", "b"], ["c", "d"]]), {}, TypeError, "integer array"),
    (np.zeros((4, 4), int), {"exclude": (0,)}, ValueError, "every pixel is excluded"),
    (np.ones((4, 4), int), {"method": "qhull"}, ValueError, "method must be one of"),
    (np.ones((4, 4), int), {"spacing": (1, 2, 3)}, ValueError, "spacing must be one number or 2"),
    (np.ones((4, 4), int), {"spacing": -1}, ValueError, "positive"),
    (np.ones((4, 4), int), {"exclude": (0.5,)}, TypeError, "integer material ids"),
])
def test_bad_input(labels, kwargs, error, match):
    with pytest.raises(error, match=match):
        mesh_labels(labels, **kwargs)


@pytest.mark.parametrize("kwargs,error,match", [
    ({"method": "qhull"}, ValueError, "method must be one of"),
    ({"connectivity": 4}, ValueError, "connectivity must be 1..3"),
    ({"connectivity": 1}, ValueError, "templates need balance across faces and edges"),
    ({"spacing": (1, 2)}, ValueError, "spacing must be one number or 3"),
    ({"exclude": ("a",)}, TypeError, "integer material ids"),
])
def test_mesh_tree_checks_its_arguments(kwargs, error, match):
    tree = build_tree(blobs((6, 5, 7), 3, seed=2, sigma=1.0))
    with pytest.raises(error, match=match):
        mesh_tree(tree, **kwargs)
    with pytest.raises(TypeError, match="tree must be a RegionTree"):
        mesh_tree(np.ones((4, 4), int))


def test_mesh_tree_equals_mesh_labels():
    lab = blobs((9, 7, 6), 3, seed=5, sigma=1.0)
    a, b = mesh_labels(lab, exclude=(0,)), mesh_tree(build_tree(lab), exclude=[0])
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_array_equal(a.points, b.points)


def test_whole_valued_floats_and_bools_are_accepted():
    lab = np.array([[1.0, 2.0], [2.0, 2.0]])
    assert check_mesh(mesh_labels(lab), lab.astype(int))["all_passed"]
    assert mesh_labels(np.eye(4, dtype=bool)).n_cells > 0


# --------------------------------------------------- "no silent wrong result" cases


@pytest.mark.parametrize("spacing", [1e-300, 1e300, (1.0, 1e-300, 1.0), (1e300, 1.0, 1.0)])
def test_spacing_that_overflows_or_underflows_is_refused(spacing):
    lab = blobs((6, 5, 7), 3, seed=2, sigma=1.0)
    with pytest.raises(ValueError, match="between 1e-30 and 1e[+]30.*other units"):
        mesh_labels(lab, spacing=spacing)


@pytest.mark.parametrize("spacing", [1e-30, 1e30, (1e-30, 1e30, 1.0)])
def test_spacing_at_the_ends_of_the_range_gives_finite_quality(spacing):
    lab = blobs((6, 5, 7), 3, seed=2, sigma=1.0)
    # aspect 1e60 cannot be subdivided (the default refuses it): stretch the voxels
    mesh = mesh_labels(lab, spacing=spacing, subdivide=False)
    for name, values in mesh.cell_data.items():
        if values.dtype.kind == "f":
            assert np.isfinite(values).all(), name
    assert check_mesh(mesh, lab)["all_passed"]


def test_uint64_labels_above_int64_are_refused_not_called_negative():
    lab = np.ones((4, 4), np.uint64)
    lab[1, 1] = 2**64 - 1
    with pytest.raises(ValueError, match="above 9223372036854775807") as info:
        mesh_labels(lab)
    assert "negative" not in str(info.value)


@pytest.mark.parametrize("dtype", [np.uint8, np.int8, np.uint16, np.uint64, np.int64, bool])
def test_labels_mesh_the_same_in_every_integer_dtype(dtype):
    lab = (blobs((6, 5, 7), 2, seed=2, sigma=1.0) > 0) if dtype is bool else \
        blobs((6, 5, 7), 3, seed=2, sigma=1.0)
    ref = mesh_labels(lab.astype(np.int64))
    mesh = mesh_labels(lab.astype(dtype))
    np.testing.assert_array_equal(mesh.cells, ref.cells)
    np.testing.assert_array_equal(mesh.material, ref.material)


def test_labels_are_not_copied_before_meshing():
    from napari_swa_imesh._region_tree import _signed_labels, build_tree

    lab = blobs((8, 8, 8), 3, seed=2, sigma=1.0).astype(np.uint8)
    work = _signed_labels(lab)
    assert work.dtype == np.int8 and np.shares_memory(work, lab)
    # the top bit in use: one wider copy, and the same tree
    high = lab.astype(np.uint8) + np.uint8(200)
    assert _signed_labels(high).dtype == np.int16
    a, b = build_tree(high), build_tree(high.astype(np.int64))
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_array_equal(a.origin, b.origin)
