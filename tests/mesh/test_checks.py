"""The mesh checks detect broken meshes: each check must be able to fail."""

import dataclasses

import numpy as np
import pytest
from imesh_cases import blobs

from napari_swa_imesh.mesh.checks._checks import check_mesh, rasterize_materials
from napari_swa_imesh.mesh.mesher._imesh import mesh_labels

LABELS = {2: blobs((12, 10), 3, seed=1, sigma=1.5), 3: blobs((6, 7, 8), 3, seed=2, sigma=1.0)}


def _broken(mesh, **changes):
    if len(changes.get("cells", mesh.cells)) != mesh.n_cells:  # per-cell data no longer fit
        changes.setdefault("cell_data", {})
    return dataclasses.replace(mesh, **changes)


@pytest.fixture(params=[2, 3])
def good(request):
    lab = LABELS[request.param]
    return mesh_labels(lab, spacing=0.5), lab


def test_good_mesh_passes(good):
    mesh, lab = good
    checks = check_mesh(mesh, lab)
    assert checks["all_passed"]
    assert checks["n_boundary_facets_off_box"] == 0 and checks["volume_error"] == pytest.approx(0)


def test_dropped_element_fails(good):
    mesh, lab = good
    k = mesh.n_cells // 2
    keep = np.arange(mesh.n_cells) != k
    broken = _broken(mesh, cells=mesh.cells[keep], material=mesh.material[keep])
    checks = check_mesh(broken, lab)
    assert not checks["conforming"] and checks["n_unmatched_facets"] > 0
    assert not checks["volume_sum"] and checks["volume_error"] < 0
    assert not checks["all_passed"]


def test_flipped_element_fails(good):
    mesh, lab = good
    cells = mesh.cells.copy()
    cells[3, [0, 1]] = cells[3, [1, 0]]
    checks = check_mesh(_broken(mesh, cells=cells), lab)
    assert not checks["positive_volume"] and checks["min_volume"] < 0
    assert not checks["volume_sum"] and not checks["all_passed"]


def test_overlapping_elements_fail():
    from napari_swa_imesh.mesh.model._types import Mesh

    points = np.array([[0.0, 0], [1, 0], [0, 1], [1, 1]])
    good = Mesh(points, np.array([[0, 1, 3], [0, 3, 2]]), np.array([1, 1]), spacing=(1.0, 1.0),
                shape=(1, 1))
    assert check_mesh(good, np.ones((1, 1), int))["all_passed"]
    # both triangles on the same side of their shared edge (0, 1)
    bad = dataclasses.replace(good, cells=np.array([[0, 1, 3], [0, 1, 2]]))
    checks = check_mesh(bad, np.ones((1, 1), int))
    assert checks["n_misoriented_facets"] == 1 and not checks["conforming"]
    assert checks["positive_volume"] and checks["volume_sum"]


def test_duplicated_element_fails(good):
    mesh, lab = good
    broken = _broken(mesh, cells=np.concatenate([mesh.cells, mesh.cells[:1]]),
                     material=np.concatenate([mesh.material, mesh.material[:1]]))
    checks = check_mesh(broken, lab)
    assert not checks["conforming"] and not checks["volume_sum"]


def test_wrong_material_fails(good):
    mesh, lab = good
    material = mesh.material.copy()
    material[0] = material[0] + 1
    checks = check_mesh(_broken(mesh, material=material), lab)
    assert not checks["labels_recovered"] and checks["n_pixels_wrong"] > 0
    assert checks["conforming"] and checks["volume_sum"]


def test_element_across_leaves_fails(good):
    mesh, lab = good
    # merge two pixels' worth of mesh: move the vertex of a corner element outward
    points = mesh.points.copy()
    corner = np.argmin(points.sum(axis=1))
    points[corner] -= 0.25  # outside the image box: outside every leaf
    checks = check_mesh(_broken(mesh, points=points), lab)
    assert not checks["inside_one_leaf"]
    assert not checks["all_passed"]


def test_exclusion_must_be_declared():
    lab = LABELS[2]
    mesh = mesh_labels(lab, exclude=(0,))
    assert check_mesh(mesh, lab, exclude=(0,))["all_passed"]
    checks = check_mesh(mesh, lab)
    assert not checks["labels_recovered"] and not checks["conforming"] and not checks["volume_sum"]


def test_rasterize_round_trip_3d():
    lab = LABELS[3]
    np.testing.assert_array_equal(rasterize_materials(mesh_labels(lab, spacing=(1, 2, 3))), lab)


def test_dimension_mismatch():
    mesh = mesh_labels(LABELS[2])
    with pytest.raises(ValueError, match="needs a 3-D mesh"):
        check_mesh(mesh, LABELS[3])


def test_chunked_passes_give_the_same_answer(monkeypatch):
    from napari_swa_imesh.mesh.checks import _checks, _facets

    lab = LABELS[3]
    mesh = mesh_labels(lab, exclude=(0,))
    keep = np.arange(mesh.n_cells) != 7
    broken = _broken(mesh, cells=mesh.cells[keep], material=mesh.material[keep])
    whole = [check_mesh(m, lab, exclude=(0,)) for m in (mesh, broken)]
    monkeypatch.setattr(_facets, "_KEYS_PER_PASS", 97)
    monkeypatch.setattr(_checks, "_CELLS_PER_CHUNK", 13)
    monkeypatch.setattr(_facets, "_CHUNK", 11)
    monkeypatch.setattr(_facets, "_RUN_BLOCK", 7)
    chunked = [check_mesh(m, lab, exclude=(0,)) for m in (mesh, broken)]
    assert chunked == whole
    monkeypatch.setattr(_facets, "_MAX_PASSES", 1)       # ids ranked, not packed
    assert [check_mesh(m, lab, exclude=(0,)) for m in (mesh, broken)] == whole
    assert whole[0]["all_passed"] and not whole[1]["conforming"]


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_or_inf_quality_fails_the_checks(good, bad):
    # spacing that over- or underflowed used to give quality inf and NaN angles while
    # every check said ok
    mesh, lab = good
    quality = mesh.quality.copy()
    quality[0] = bad
    broken = _broken(mesh, cell_data={**mesh.cell_data, "quality": quality})
    checks = check_mesh(broken, lab)
    assert not checks["finite"] and checks["n_nonfinite_values"] == 1
    assert not checks["all_passed"]
    assert check_mesh(mesh, lab)["finite"]


def test_report_is_typed_and_reads_like_the_old_dict(good):
    from napari_swa_imesh.mesh.checks._checks import MeshChecks

    mesh, lab = good
    checks = check_mesh(mesh, lab)
    assert isinstance(checks, MeshChecks) and checks.all_passed is True
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign"):
        checks.conforming = False
    keys = ["n_unused_points", "min_volume", "positive_volume", "volume_error", "volume_sum",
            "n_facets_shared_3plus", "n_misoriented_facets", "n_boundary_facets_off_box",
            "n_unmatched_facets", "conforming", "n_outside_leaf", "inside_one_leaf",
            "n_pixels_wrong", "labels_recovered", "n_nonfinite_values", "finite", "all_passed"]
    assert list(checks) == list(checks.to_dict()) == keys  # the --json keys, in order
    assert dict(checks) == checks.to_dict() and checks["conforming"] is checks.conforming
    assert all(type(v) in (bool, int, float) for v in checks.to_dict().values())


def test_a_given_tree_is_used_and_must_match_the_labels(good):
    from napari_swa_imesh import build_tree

    mesh, lab = good
    assert check_mesh(mesh, lab, tree=build_tree(lab)) == check_mesh(mesh, lab)
    with pytest.raises(ValueError, match="tree was built from an image of shape"):
        check_mesh(mesh, lab, tree=build_tree(lab[:-1]))
    with pytest.raises(TypeError, match="tree must be a RegionTree"):
        check_mesh(mesh, lab, tree=lab)


def test_overlapping_tetrahedra_fail():
    """Two tetrahedra on the same side of their shared face: caught by the side bits."""
    from napari_swa_imesh.mesh.model._types import Mesh

    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1], [0.3, 0.3, 0.5]])
    mesh = Mesh(points, np.array([[0, 1, 2, 3], [0, 1, 2, 4]]), np.array([1, 1]),
                spacing=(1.0,) * 3, shape=(1, 1, 1))
    mesh = dataclasses.replace(mesh, cells=np.where(
        (np.sign(_volumes(mesh)) < 0)[:, None], mesh.cells[:, [1, 0, 2, 3]], mesh.cells))
    checks = check_mesh(mesh, np.ones((1, 1, 1), int))
    assert checks["positive_volume"] and checks["n_misoriented_facets"] == 1
    assert not checks["conforming"]


def _volumes(mesh):
    from napari_swa_imesh.mesh.model._quality import signed_volumes

    return signed_volumes(mesh.points, mesh.cells)


def test_corner_order_does_not_matter_but_orientation_does(good):
    """Even permutations of each cell's corners keep every check; odd ones invert cells."""
    mesh, lab = good
    d = mesh.ndim
    rng = np.random.default_rng(d)
    perms = [p for p in __import__("itertools").permutations(range(d + 1))]
    even = np.array([p for p in perms if _parity(p) == 0])
    odd = np.array([p for p in perms if _parity(p) == 1])
    rows = np.arange(mesh.n_cells)[:, None]
    shuffled = mesh.cells[rows, even[rng.integers(0, len(even), mesh.n_cells)]]
    assert check_mesh(_broken(mesh, cells=shuffled), lab) == check_mesh(mesh, lab)
    inverted = mesh.cells[rows, odd[rng.integers(0, len(odd), mesh.n_cells)]]
    checks = check_mesh(_broken(mesh, cells=inverted), lab)
    assert not checks["positive_volume"] and checks["n_misoriented_facets"] == 0


def _parity(p) -> int:
    return sum(p[i] > p[j] for i in range(len(p)) for j in range(i + 1, len(p))) % 2


def test_gap_filled_by_an_overlap_in_one_leaf_fails(good):
    """A dropped element replaced by a copy of its neighbour in the same leaf keeps the
    leaf's volume only when the volumes agree; the facets still see the hole."""
    mesh, lab = good
    leaf = mesh.cell_data["leaf"]
    volumes = _volumes(mesh)
    # two elements of one leaf with equal volumes
    key = np.stack([leaf, np.round(volumes * 1e9)], axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    a = first[counts >= 2][0]
    b = np.flatnonzero((key == key[a]).all(axis=1))[1]
    cells = mesh.cells.copy()
    cells[b] = cells[a]
    checks = check_mesh(_broken(mesh, cells=cells), lab)
    assert checks["volume_sum"] and checks["labels_recovered"]  # volumes cannot tell
    assert not checks["conforming"] and checks["n_unmatched_facets"] > 0
    assert checks["n_facets_shared_3plus"] + checks["n_misoriented_facets"] > 0


def test_element_moved_to_another_leaf_breaks_the_labels(good):
    mesh, lab = good
    points = mesh.points.copy()
    shift = np.zeros(mesh.ndim)
    shift[-1] = mesh.spacing[-1]
    cells = mesh.cells.copy()
    # a copy of one element's corners, moved by one pixel, replaces it
    k = mesh.n_cells // 3
    new = np.arange(len(points), len(points) + mesh.ndim + 1)
    points = np.concatenate([points, mesh.points[cells[k]] + shift])
    cells[k] = new
    checks = check_mesh(_broken(mesh, points=points, cells=cells), lab)
    assert not checks["labels_recovered"] and checks["n_pixels_wrong"] > 0
    assert not checks["conforming"] and not checks["all_passed"]
