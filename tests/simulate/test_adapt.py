"""The default's adaptive step: meshes refined where marked stay exact IMESH meshes, the
indicator sees flux jumps and nothing else, marking is Doerfler's, and adapting moves
k_eff towards a much finer solution. These pin the adaptive step itself (interval=False:
the interval's own refinement, after it, is tested in test_dual.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from simulate_cases import blobs

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import check_mesh, mesh_labels, quality_bounds
from napari_swa_imesh.mesh.mesher._adapt import refine_marked
from napari_swa_imesh.simulate import _adapt, simulate
from napari_swa_imesh.simulate._adapt import doerfler, flux_jump_indicator


@settings(max_examples=16, deadline=None)
@given(st.sampled_from([2, 3]), st.integers(0, 10_000), st.floats(0.02, 0.6),
       st.sampled_from([(1.0, 1.0, 1.0), (2.5, 1.0, 1.0), (1.0, 1.0, 8.0), (0.7, 1.3, 1.0)]),
       st.sampled_from([{}, {"refine": 1}, {"exclude": [1]}, {"max_size": 3.0},
                        {"periodic": True}]))
def test_marked_refinement_is_a_conforming_exact_mesh_within_its_bound(d, seed, share, spacing,
                                                                       options):
    shape = (14, 12, 10)[:d] if d == 3 else (30, 26)
    labels = blobs(shape, seed=seed)
    mesh = mesh_labels(labels, spacing=spacing[:d], **options)
    marked = np.random.default_rng(seed).random(mesh.n_cells) < share
    fine = refine_marked(labels, mesh, marked)
    assert check_mesh(fine, labels, exclude=options.get("exclude", ())).all_passed
    if "max_size" in options:
        edges = fine.points[fine.cells][:, :, None] - fine.points[fine.cells][:, None]
        assert np.linalg.norm(edges, axis=-1).max() <= options["max_size"] * (1 + 1e-9)
    if options.get("periodic"):
        _assert_matching_faces(fine)
    if options.get("exclude"):
        return
    voxel = float(np.prod(spacing[:d]))
    corners = fine.points[fine.cells]
    edges = corners[:, 1:] - corners[:, :1]
    volumes = np.bincount(fine.material,
                          weights=np.abs(np.linalg.det(edges)) / (2 if d == 2 else 6))
    np.testing.assert_allclose(volumes[1:], np.bincount(labels.ravel())[1:] * voxel, rtol=1e-9)
    bound = quality_bounds(d, spacing[:d])["quality"][1]
    assert fine.quality.max() <= bound * (1 + 1e-9)
    assert fine.n_cells > mesh.n_cells and fine.recipe.adapted.marked_elements == marked.sum()


def _assert_matching_faces(mesh):
    from napari_swa_imesh.mesh import facet_groups

    groups = facet_groups(mesh)
    lo, hi = mesh.image_box()
    d = mesh.ndim
    for name, axis in zip("xyz"[:d], range(d - 1, -1, -1)):
        def facet_set(group, shift, axis=axis):
            corners = mesh.points[group.facets].copy()
            corners[:, :, axis] -= shift
            keys = np.sort(np.round(corners * 1e6).astype(np.int64).view(
                [("", np.int64)] * d).reshape(len(corners), d), axis=1)
            return {tuple(row.tolist()) for row in keys}
        assert facet_set(groups[f"{name}min"], lo[axis]) == facet_set(groups[f"{name}max"],
                                                                      hi[axis])


def test_nothing_marked_keeps_the_elements():
    labels = blobs((20, 18))
    mesh = mesh_labels(labels)
    same = refine_marked(labels, mesh, np.zeros(mesh.n_cells, bool))
    assert same.n_cells == mesh.n_cells
    np.testing.assert_allclose(np.sort(same.points, axis=0), np.sort(mesh.points, axis=0))


def test_refusals_say_what_to_pass(tmp_path):
    labels = blobs((12, 12))
    mesh = mesh_labels(labels)
    with pytest.raises(ValueError, match="one flag per element"):
        refine_marked(labels, mesh, np.ones(3, bool))
    with pytest.raises(ValueError, match="pass the labels the mesh was made from"):
        refine_marked(labels[:, ::-1].copy(), mesh, np.ones(mesh.n_cells, bool))
    with pytest.raises(ValueError, match="the labels have shape"):
        refine_marked(labels[:10], mesh, np.ones(mesh.n_cells, bool))
    with pytest.raises(ValueError, match="not coarsened"):
        refine_marked(labels, mesh_labels(labels, coarsen=1), np.ones(36, bool))
    finest = mesh_labels(np.ones((2, 2), np.uint8) + np.eye(2, dtype=np.uint8), refine=4)
    with pytest.raises(ValueError, match="finest"):
        refine_marked(np.ones((2, 2), np.uint8) + np.eye(2, dtype=np.uint8), finest,
                      np.ones(finest.n_cells, bool))
    with pytest.raises(ValueError, match="needs a label image"):
        simulate(mesh, {1: 1, 2: 2, 3: 3}, adapt=1)
    with pytest.raises(ValueError, match="adapt must be"):
        simulate(labels, {1: 1, 2: 2, 3: 3}, adapt=3)


def test_the_indicator_is_zero_where_the_field_is_exact_and_not_elsewhere():
    # series layers: P1 is exact, the normal flux continuous, no jump anywhere
    layers = np.ones((10, 12), np.uint8)
    layers[:, 6:] = 2
    r = simulate(layers, {1: 1.0, 2: 7.0}, order=1, adapt=0, axes="x")
    assert flux_jump_indicator(r.mesh, [r.flux["x"]]).max() < 1e-20
    # along the layers too: the tangential flux jumps at the interface and must not count
    # (it would if the flux components met the normals in the wrong axis order)
    r = simulate(layers, {1: 1.0, 2: 7.0}, order=1, adapt=0, axes="y")
    assert flux_jump_indicator(r.mesh, [r.flux["y"]]).max() < 1e-20
    assert not doerfler(flux_jump_indicator(r.mesh, [r.flux["y"]])).any()
    labels = blobs((16, 16))
    r = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1}, order=1, adapt=0)
    eta = flux_jump_indicator(r.mesh, [r.flux["x"], r.flux["y"]])
    assert eta.min() >= 0 and eta.sum() > 1e-3
    # largest where materials meet
    interface = np.zeros(r.mesh.n_cells, bool)
    touching = np.isin(r.mesh.cells, r.mesh.cells[r.mesh.material != 1]).any(axis=1)
    interface[(r.mesh.material == 1) & touching] = True
    assert eta[interface].mean() > 5 * eta[~interface & (r.mesh.material == 1)].mean()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0, 100), min_size=1, max_size=40), st.floats(0.05, 1.0))
def test_doerfler_marks_a_smallest_set_holding_theta(values, theta):
    eta = np.asarray(values)
    marked = doerfler(eta, theta)
    if eta.sum() <= _adapt.FLOOR:       # an exact field: round-off, nothing marked
        assert not marked.any()
        return
    assert eta[marked].sum() >= theta * eta.sum() * (1 - 1e-12)
    # no smaller set does: the largest (count - 1) values fall short, unless tied
    k = int(marked.sum())
    top = np.sort(eta)[::-1]
    assert top[:k - 1].sum() < theta * eta.sum() or top[k - 1] == top[k - 2]
    assert eta[marked].min() >= eta[~marked].max(initial=0)


def test_adapting_moves_k_eff_towards_a_much_finer_solution():
    labels = blobs((24, 24), sigma=2.0, seed=3)
    k = {1: 1.0, 2: 10.0, 3: 0.1}
    fine = simulate(labels, k, order=2, adapt=0, refine=3, axes="x").k_eff["x"]
    p2 = simulate(labels, k, order=2, adapt=0, axes="x")
    default = simulate(labels, k, axes="x", interval=False)
    assert default.choice == "P2, 1 adaptive step" and default.adapt == 1
    assert abs(default.k_eff["x"] - fine) < 0.7 * abs(p2.k_eff["x"] - fine)
    assert default.dofs < 2 * p2.dofs
    # conforming: every discretisation lies above the exact value, the finer the lower
    assert fine < default.k_eff["x"] < p2.k_eff["x"]
    # a second step refines the adapted mesh, not the labels' own tree
    two = simulate(labels, k, order=2, adapt=2, axes="x")
    assert two.mesh.recipe.adapted.steps == 2 and check_mesh(two.mesh, labels).all_passed
    assert fine < two.k_eff["x"] < default.k_eff["x"]
    with pytest.raises(ValueError, match="adapted before"):
        refine_marked(labels, default.mesh, np.ones(default.mesh.n_cells, bool))


def test_the_default_is_the_same_for_the_transposed_and_relabelled_image():
    labels = blobs((18, 22), seed=5)
    k = {1: 1.0, 2: 10.0, 3: 0.1}
    a = simulate(labels, k, interval=False)
    b = simulate(np.ascontiguousarray(labels.T), k, interval=False)
    assert a.k_eff["x"] == pytest.approx(b.k_eff["y"], rel=1e-9)
    assert a.k_eff["y"] == pytest.approx(b.k_eff["x"], rel=1e-9)
    c = simulate((4 - labels).astype(np.uint8), {3: 1.0, 2: 10.0, 1: 0.1}, interval=False)
    assert c.k_eff == pytest.approx(a.k_eff, rel=1e-9) and c.dofs == a.dofs


def test_the_default_falls_back_within_its_budget_and_says_why(monkeypatch, tmp_path, capsys):
    labels = blobs((20, 20))
    k = {1: 1.0, 2: 10.0, 3: 0.1}
    vertices = len(mesh_labels(labels).points)
    p2 = _adapt.P2_PER_VERTEX[2] * vertices
    monkeypatch.setattr(_adapt, "P2_BUDGET", int(p2 * 1.2))      # P2 fits, adapted not
    r = simulate(labels, k, axes="x", interval=False)
    assert r.order == 2 and r.adapt == 0 and "not adapted" in r.choice
    monkeypatch.setattr(_adapt, "P2_BUDGET", int(p2 * 0.5))      # not even P2
    r = simulate(labels, k, axes="x", interval=False)
    assert r.order == 1 and r.adapt == 0 and "above the default's budget" in r.choice
    np.save(tmp_path / "l.npy", labels)
    assert main(["simulate", str(tmp_path / "l.npy"), "-k", "1=1", "2=10", "3=0.1",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["order"] == 1 and "budget" in out["choice"]
    # P2 asked for: adapting stays within the budget unless asked for too
    assert simulate(labels, k, axes="x", order=2).adapt == 0
    assert simulate(labels, k, axes="x", order=2, adapt=1).adapt == 1


def test_adapting_keeps_the_world_placement_and_the_periodic_default_does_not_adapt():
    from napari_swa_imesh.mesh import to_meshio

    labels = blobs((12, 10))
    affine = np.array([[0.0, -1.5, 4.0], [2.0, 0.0, -3.0], [0.0, 0.0, 1.0]])
    mesh = mesh_labels(labels, affine=affine)
    r = simulate(mesh, {1: 1.0, 2: 10.0, 3: 0.1}, labels=labels)
    assert r.adapt == 1 and r.mesh.world is not None
    np.testing.assert_allclose(to_meshio(r.mesh).points.min(axis=0),
                               to_meshio(mesh).points.min(axis=0))
    np.testing.assert_allclose(to_meshio(r.mesh).points.max(axis=0),
                               to_meshio(mesh).points.max(axis=0))
    # periodic: a finer lattice refines whole box faces, so the default does not adapt;
    # asked for, the adapted mesh keeps its faces matched
    periodic = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1}, protocol="periodic")
    assert periodic.adapt == 0 and periodic.order == 2
    asked = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1}, protocol="periodic", adapt=1)
    assert asked.adapt == 1
    _assert_matching_faces(asked.mesh)


def test_the_finest_refine_level_bounds_the_steps():
    labels = blobs((6, 6))
    assert simulate(labels, {1: 1, 2: 2, 3: 3}, refine=4).adapt == 0     # default: none
    with pytest.raises(ValueError, match="would pass the finest refine level 4"):
        simulate(labels, {1: 1, 2: 2, 3: 3}, refine=3, adapt=2)
