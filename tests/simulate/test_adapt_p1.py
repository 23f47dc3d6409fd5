"""P1's budgeted adaptive steps: the leaves of largest indicator are split, as many as keep
the vertices within the target; the meshes stay exact IMESH meshes; ``order=1`` with
``adapt="auto"`` takes two steps within 3x the vertices and moves k_eff towards a much
finer solution; over its budget it does not adapt and says so."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from simulate_cases import blobs

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import check_mesh, mesh_labels, quality_bounds
from napari_swa_imesh.simulate import _adapt, simulate
from napari_swa_imesh.simulate._adapt import refine_within

K = {1: 1.0, 2: 10.0, 3: 0.1}


@settings(max_examples=12, deadline=None)
@given(st.sampled_from([2, 3]), st.integers(0, 10_000), st.floats(1.0, 3.0),
       st.sampled_from([(1.0, 1.0, 1.0), (2.5, 1.0, 1.0), (0.7, 1.3, 1.0)]),
       st.sampled_from([{}, {"refine": 1}, {"exclude": [1]}]))
@example(3, 0, 2.0, (0.7, 1.3, 1.0), {})   # scattered splits: each try overshot, none kept
def test_the_largest_leaves_are_split_within_the_target_and_the_mesh_stays_exact(
        d, seed, growth, spacing, options):
    labels = blobs((14, 12, 10) if d == 3 else (30, 26), seed=seed)
    mesh = mesh_labels(labels, spacing=spacing[:d], **options)
    leaf = np.asarray(mesh.cell_data["leaf"])
    rng = np.random.default_rng(seed)
    indicator = rng.random(leaf.max() + 1) * np.isin(np.arange(leaf.max() + 1), leaf)
    target = growth * len(mesh.points)
    fine, _ = refine_within(labels, mesh, indicator, target)
    assert len(fine.points) <= target
    assert check_mesh(fine, labels, exclude=options.get("exclude", ())).all_passed
    assert fine.quality.max() <= quality_bounds(d, spacing[:d])["quality"][1] * (1 + 1e-9)
    # the split leaves are the top of the ranking: their elements are the marked ones
    split = fine.recipe.adapted.split_leaves
    top = np.argsort(indicator)[::-1][:split]
    assert fine.recipe.adapted.marked_elements == np.isin(leaf, top).sum()
    if target - len(mesh.points) >= 4 * _adapt.VERTICES_PER_SPLIT * 2 ** d:
        assert split > 0 and fine.n_cells > mesh.n_cells


def test_no_room_or_an_exact_field_splits_nothing():
    labels = blobs((16, 14))
    mesh = mesh_labels(labels)
    leaf = np.asarray(mesh.cell_data["leaf"])
    ones = np.ones(leaf.max() + 1)
    same, _ = refine_within(labels, mesh, ones, len(mesh.points) + 1)
    assert same.n_cells == mesh.n_cells and same.recipe.adapted.split_leaves == 0
    same, _ = refine_within(labels, mesh, np.zeros_like(ones), 3 * len(mesh.points))
    assert same.n_cells == mesh.n_cells
    # layers across the flux: the field is exact, nothing is refined, k_eff is harmonic
    layers = np.repeat(np.array([[1, 2, 2, 1, 1, 2]]), 5, axis=0)
    r = simulate(layers, {1: 1.0, 2: 4.0}, axes="x", order=1, interval=False)
    assert r.adapt == 2 and r.mesh.n_cells == mesh_labels(layers).n_cells
    assert r.k_eff["x"] == pytest.approx(6 / (3 / 1.0 + 3 / 4.0), rel=1e-9)


def test_p1_asked_adapts_twice_within_3x_the_vertices_towards_a_finer_solution():
    labels = blobs((12, 12, 12), sigma=2.0, seed=4)
    vertices = len(mesh_labels(labels).points)
    fine = simulate(labels, K, order=2, adapt=0, refine=2, axes="x").k_eff["x"]
    plain = simulate(labels, K, order=1, adapt=0, axes="x")
    auto = simulate(labels, K, order=1, axes="x", interval=False)
    assert auto.choice == f"P1 (asked), 2 adaptive steps within {_adapt.P1_GROWTH:g}x the vertices"
    assert auto.order == 1 and auto.adapt == 2 and auto.dofs == len(auto.mesh.points)
    assert vertices < auto.dofs <= _adapt.P1_GROWTH * vertices <= 3 * vertices
    assert check_mesh(auto.mesh, labels).all_passed
    # conforming: above the exact value, and much closer to it than P1 on the first mesh
    assert fine < auto.k_eff["x"] < plain.k_eff["x"]
    assert auto.k_eff["x"] - fine < 0.8 * (plain.k_eff["x"] - fine)


def test_p1_over_its_budget_is_not_adapted_and_says_why(monkeypatch, tmp_path, capsys):
    labels = blobs((20, 20))
    vertices = len(mesh_labels(labels).points)
    monkeypatch.setattr(_adapt, "P1_BUDGET", 2 * vertices)
    r = simulate(labels, K, axes="x", order=1, interval=False)
    assert r.adapt == 0 and "above" not in r.choice and "P1 budget" in r.choice
    monkeypatch.setattr(_adapt, "P1_BUDGET", 3 * vertices)
    np.save(tmp_path / "l.npy", labels)
    assert main(["simulate", str(tmp_path / "l.npy"), "-k", "1=1", "2=10", "3=0.1",
                 "--order", "1", "--axes", "x", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["order"] == 1 and f"within {_adapt.P1_GROWTH:g}x the vertices" in out["choice"]
    # a mesh without its labels, or adapt 0, stays as it is
    assert simulate(mesh_labels(labels), K, axes="x", order=1).adapt == 0
    assert simulate(labels, K, axes="x", order=1, adapt=0).dofs == vertices


def test_p1_budget_counts_from_the_labels_on_voxel_cells_not_the_subdivided_mesh():
    # 1 / 0.8 / 1.2 (float32) cuts each voxel into 2 x 2 x 3 cells; the budget is still
    # P1_GROWTH times the labels' voxel-lattice mesh, so the subdivision does not
    # multiply the unknowns the default buys
    labels = blobs((10, 12, 8), sigma=2.0, seed=4)
    spacing = tuple(float(np.float32(s)) for s in (1.0, 0.8, 1.2))
    first = mesh_labels(labels, spacing=spacing)
    assert first.recipe.lattice.factors == (2, 2, 3)
    voxel = len(mesh_labels(labels, spacing=spacing, subdivide=False).points)
    assert _adapt.voxel_lattice_vertices(labels, first) == voxel
    iso = simulate(labels, K, order=1, axes="x", interval=False)
    aniso = simulate(labels, K, order=1, axes="x", spacing=spacing, interval=False)
    assert iso.dofs <= _adapt.P1_GROWTH * voxel           # the isotropic rule, unchanged
    assert aniso.dofs <= max(len(first.points), _adapt.P1_GROWTH * voxel)
    assert aniso.dofs < 0.5 * _adapt.P1_GROWTH * len(first.points)
    if aniso.adapt == 0:
        assert "labels on voxel cells" in aniso.choice
    # on cubic voxels the reference is the first mesh itself
    plain = mesh_labels(labels)
    assert _adapt.voxel_lattice_vertices(labels, plain) == len(plain.points)
