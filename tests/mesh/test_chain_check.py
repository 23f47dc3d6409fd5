"""The sort-free checks of lattice meshes: the same verdict as the full check, and every
mutation of a good mesh refused (the full check then says what is wrong)."""

import dataclasses

import numpy as np
import pytest
from imesh_cases import blobs, cases

from napari_swa_imesh import build_tree
from napari_swa_imesh.mesh.checks import _chain_check, _checks
from napari_swa_imesh.mesh.checks._checks import check_mesh
from napari_swa_imesh.mesh.mesher._imesh import mesh_labels

LABELS = {2: blobs((14, 11), 3, seed=4, sigma=1.5), 3: blobs((7, 6, 9), 3, seed=5, sigma=1.0)}


@pytest.fixture
def spy(monkeypatch):
    """Results of every lattice_checks call (None: not taken or failed)."""
    seen = []

    def wrapped(*args):
        seen.append(_chain_check.lattice_checks(*args))
        return seen[-1]

    monkeypatch.setattr(_checks, "lattice_checks", wrapped)
    return seen


def _fast(mesh, lab, exclude=()):
    """lattice_checks on a mesh of spacing 1 (points are pixel units)."""
    exclude = np.asarray(exclude, dtype=np.int64)
    n_included = lab.size - int(np.isin(lab, exclude).sum())
    return _chain_check.lattice_checks(mesh.points, mesh.cells, mesh.material, lab, exclude,
                                       build_tree(lab), n_included)


@pytest.mark.parametrize("dim", [2, 3])
def test_same_verdict_as_the_full_check_and_taken(dim, spy):
    for name, lab in cases(dim):
        for options in ({}, {"exclude": (0,)}, {"spacing": (0.5, 2.0, 1.0)[:dim]},
                        {"exclude": (1,), "spacing": (0.5, 2.0, 1.0)[:dim]}):
            if "exclude" in options and not np.isin(lab, options["exclude"]).any() \
                    or np.isin(lab, options.get("exclude", ())).all():
                continue
            mesh = mesh_labels(lab, **options)
            spy.clear()
            fast = check_mesh(mesh, lab, exclude=options.get("exclude", ()))
            assert fast.all_passed, (name, options)
            assert any(r is not None for r in spy), (name, options)   # no sort was needed
            assert fast == check_mesh(mesh, lab, exclude=options.get("exclude", ()),
                                      full=True), (name, options)


@pytest.mark.parametrize("dim", [2, 3])
def test_periodic_refined_and_capped_meshes_agree_with_the_full_check(dim, spy):
    """--refine puts points at 2**-K pixel: checked on that finer lattice, no sort."""
    lab = LABELS[dim]
    for options in ({"periodic": True}, {"refine": 1}, {"refine": 2, "exclude": (0,)},
                    {"max_size": 2.0}, {"refine": 1, "spacing": (0.5, 2.0, 1.0)[:dim]}):
        mesh = mesh_labels(lab, **options)
        spy.clear()
        fast = check_mesh(mesh, lab, exclude=options.get("exclude", ()))
        assert fast.all_passed and spy[-1] is not None, options
        assert fast == check_mesh(mesh, lab, exclude=options.get("exclude", ()), full=True)


@pytest.fixture(params=[2, 3])
def good(request):
    lab = LABELS[request.param]
    mesh = mesh_labels(lab)
    assert _fast(mesh, lab) is not None
    return mesh, lab


def _refused(mesh, lab, **changes):
    """The mutated mesh: the sort-free pass refuses it, and the default check reports
    exactly what the full check does, a failure."""
    if len(changes.get("cells", mesh.cells)) != mesh.n_cells:
        changes.setdefault("cell_data", {})
    broken = dataclasses.replace(mesh, **changes)
    assert _fast(broken, lab) is None
    checks = check_mesh(broken, lab)
    assert checks == check_mesh(broken, lab, full=True) and not checks.all_passed
    return checks


def test_flipped_element_is_refused(good):
    mesh, lab = good
    cells = mesh.cells.copy()
    cells[5, [0, 1]] = cells[5, [1, 0]]
    assert not _refused(mesh, lab, cells=cells)["positive_volume"]


def test_missing_element_is_refused(good):
    mesh, lab = good
    checks = _refused(mesh, lab, cells=np.delete(mesh.cells, 7, axis=0),
                      material=np.delete(mesh.material, 7))
    assert not checks["conforming"] and not checks["volume_sum"]


def test_wrong_material_is_refused(good):
    mesh, lab = good
    material = mesh.material.copy()
    material[3] = material[3] + 1
    assert not _refused(mesh, lab, material=material)["labels_recovered"]


def test_non_matching_face_is_refused(good):
    """One element takes a copy of a shared vertex: volumes, leaves and labels are all
    still right, only the facets no longer match (the fingerprint must see it)."""
    mesh, lab = good
    interior = np.bincount(mesh.cells.ravel()).argmax()        # the most shared vertex
    k = np.flatnonzero((mesh.cells == interior).any(axis=1))[0]
    points = np.concatenate([mesh.points, mesh.points[interior][None]])
    cells = mesh.cells.copy()
    cells[k][cells[k] == interior] = len(mesh.points)
    checks = _refused(mesh, lab, points=points, cells=cells)
    assert checks["volume_sum"] and checks["labels_recovered"] and checks["inside_one_leaf"]
    assert not checks["conforming"] and checks["n_unmatched_facets"] > 0


def test_gap_filled_by_an_overlap_is_refused(good):
    """A dropped element replaced by a copy of an element of equal volume in its leaf:
    volumes cannot tell, the facets can."""
    mesh, lab = good
    p = mesh.points[mesh.cells]
    det = np.linalg.det(p[:, 1:] - p[:, :1])
    key = np.stack([mesh.cell_data["leaf"], np.round(det * 1e6)], axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    a = first[counts >= 2][0]
    b = np.flatnonzero((key == key[a]).all(axis=1))[1]
    cells = mesh.cells.copy()
    cells[b] = cells[a]
    checks = _refused(mesh, lab, cells=cells)
    assert checks["volume_sum"] and checks["labels_recovered"] and not checks["conforming"]


def test_boundary_facet_next_to_an_included_pixel_is_refused():
    """Declaring a material excluded that the mesh covers, and dropping its elements:
    the facets around the hole stay single next to pixels that are not excluded."""
    lab = LABELS[3]
    mesh = mesh_labels(lab, exclude=(2,))
    keep = mesh.material != 1
    broken = dataclasses.replace(mesh, cells=mesh.cells[keep], material=mesh.material[keep],
                                 cell_data={})
    assert _fast(broken, lab, exclude=(2,)) is None
    checks = check_mesh(broken, lab, exclude=(2,))
    assert checks == check_mesh(broken, lab, exclude=(2,), full=True)
    assert not checks["conforming"] and checks["n_unmatched_facets"] > 0


def test_points_off_the_lattice_take_the_full_check(spy):
    lab = LABELS[2]
    mesh = mesh_labels(lab)
    moved = dataclasses.replace(mesh, points=mesh.points + 0.3)
    assert check_mesh(moved, lab) == check_mesh(moved, lab, full=True)
    assert spy == [None]


def test_refined_mesh_mutations_are_refused():
    """On the finer lattice too: a vertex split off one element, a facet of the hole left
    by dropped elements on a pixel plane next to an included pixel."""
    lab = LABELS[3]
    mesh = mesh_labels(lab, refine=1)
    interior = np.bincount(mesh.cells.ravel()).argmax()
    k = np.flatnonzero((mesh.cells == interior).any(axis=1))[0]
    cells = mesh.cells.copy()
    cells[k][cells[k] == interior] = len(mesh.points)
    points = np.concatenate([mesh.points, mesh.points[interior][None]])
    broken = dataclasses.replace(mesh, points=points, cells=cells)
    checks = check_mesh(broken, lab)
    assert checks == check_mesh(broken, lab, full=True) and not checks["conforming"]
    keep = mesh.material != 1
    holed = dataclasses.replace(mesh, cells=mesh.cells[keep], material=mesh.material[keep],
                                cell_data={})
    checks = check_mesh(holed, lab, exclude=(1,))
    assert checks == check_mesh(holed, lab, exclude=(1,), full=True)
    assert checks["conforming"] and checks["all_passed"]       # 1 excluded: a real hole
    checks = check_mesh(holed, lab, exclude=(2,))
    assert not checks["conforming"] and not checks["all_passed"]
