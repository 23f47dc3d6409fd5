"""How a mesh was made is a typed record on it (``Mesh.recipe``, ``Mesh.made``), never a
stale one: every way of changing or copying a mesh clears it unless a function carries
it on purpose, and ``info`` holds counts and timings only."""

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_swa_imesh.mesh import Mesh, clip_cells, facet_groups, mesh_labels, mesh_tree
from napari_swa_imesh.mesh.checks._facets import _sorted_groups
from napari_swa_imesh.mesh.mesher._adapt import refine_marked
from napari_swa_imesh.mesh.mesher._lattice import Lattice
from napari_swa_imesh.mesh.model._recipe import Adapted, Recipe

#: keys of the recipe that ``info`` once carried
RECIPE_KEYS = {"method", "exclude", "lattice", "max_size", "periodic", "adapted",
               "balance", "diagonal_rule", "spacing", "shape", "dim"}


def _labels(shape=(6, 7, 5), seed=0):
    return np.random.default_rng(seed).integers(0, 3, shape)


def test_the_mesher_records_what_it_was_asked():
    mesh = mesh_labels(_labels(), exclude=[0], spacing=(2.5, 1.0, 1.0), refine=1,
                       max_size=6.0, periodic=True)
    r = mesh.recipe
    assert isinstance(r, Recipe) and r.method == "template" and r.exclude == (0,)
    assert isinstance(r.lattice, Lattice) and r.lattice.factors == (2, 1, 1)
    assert r.lattice.refine == r.refine and r.max_size == 6.0 and r.periodic
    assert r.coarsen == 0 and r.adapted is None and r.remeshable and r.subdivided
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.method = "delaunay"
    coarse = mesh_labels(_labels((8, 8, 8)), coarsen=1)
    assert coarse.recipe.coarsen == 1 and not coarse.recipe.remeshable
    assert coarse.info["coarsen"]["level"] == 1          # the volume changes: counts
    delaunay = mesh_labels(_labels()[..., 0], method="delaunay")
    assert delaunay.recipe.method == "delaunay" and delaunay.made is None
    tree_mesh = mesh_tree(__import__("napari_swa_imesh").build_tree(_labels()))
    assert tree_mesh.recipe.lattice is None and not tree_mesh.recipe.remeshable


@pytest.mark.parametrize("options", [{}, {"method": "delaunay"}, {"coarsen": 1},
                                     {"spacing": (2.0, 1.0, 1.0), "refine": 1}])
def test_info_holds_counts_and_timings_only(options):
    labels = _labels((8, 8, 8))
    mesh = mesh_labels(labels[..., 0] if options.get("method") else labels, **options)
    assert not RECIPE_KEYS & set(mesh.info)
    seconds = mesh.info["seconds"]
    assert seconds and all(isinstance(v, float) for v in seconds.values())
    assert not any(k.startswith("_") for k in seconds)   # no count among the timings
    if not options.get("method"):
        assert mesh.info["n_plain_leaves"] >= 0


def _changed(mesh: Mesh, how: str) -> Mesh:
    """`mesh` changed or copied in one of the ways a caller can."""
    keep = np.arange(0, mesh.n_cells, 2)
    if how == "new points":
        mesh.points = mesh.points + 0.0
    elif how == "new cells":
        mesh.cells = mesh.cells[:, [1, 0, 2, 3]]
    elif how == "new material":
        mesh.material = mesh.material + 1
    elif how == "new cell data":
        mesh.cell_data = dict(mesh.cell_data)
    elif how == "new spacing":
        mesh.spacing = tuple(2.0 * s for s in mesh.spacing)
    elif how == "new shape":
        mesh.shape = tuple(n + 1 for n in mesh.shape)
    elif how == "replace with new points":
        return dataclasses.replace(mesh, points=mesh.points * 2.0)
    elif how == "replace with the same arrays":
        return dataclasses.replace(mesh)
    elif how == "clip":
        kept = ~clip_cells(mesh.points, mesh.cells, 0, 2.5)
        return Mesh(mesh.points, mesh.cells[kept], mesh.material[kept],
                    {k: v[kept] for k, v in mesh.cell_data.items()}, spacing=mesh.spacing,
                    shape=mesh.shape, info=mesh.info)
    elif how == "cut from arrays":
        return Mesh(mesh.points, mesh.cells[keep], mesh.material[keep],
                    {k: v[keep] for k, v in mesh.cell_data.items()}, spacing=mesh.spacing,
                    shape=mesh.shape, info=mesh.info)
    else:
        raise AssertionError(how)
    return mesh


CHANGES = ["new points", "new cells", "new material", "new cell data", "new spacing",
           "new shape", "replace with new points", "replace with the same arrays", "clip",
           "cut from arrays"]


@pytest.mark.parametrize("how", CHANGES)
def test_a_changed_or_copied_mesh_carries_no_recipe(how):
    mesh = mesh_labels(_labels())
    assert mesh.recipe is not None and mesh.made is not None
    out = _changed(mesh, how)
    assert out.recipe is None and out.made is None
    # what needs a recipe refuses it, and the facet groups take the general path
    with pytest.raises(ValueError, match="template mesh made from the labels"):
        refine_marked(_labels(), out, np.ones(out.n_cells, bool))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(CHANGES), min_size=1, max_size=3),
       st.integers(0, 2**31), st.booleans())
def test_property_no_sequence_of_changes_leaves_a_recipe(changes, seed, periodic):
    mesh = mesh_labels(_labels((5, 6, 4), seed), periodic=periodic)
    for how in changes:
        mesh = _changed(mesh, how)
        assert mesh.recipe is None and mesh.made is None
    assert facet_groups(mesh).keys() == _sorted_groups(mesh).keys()


def test_the_mesher_s_arrays_are_read_only_so_its_record_cannot_go_stale():
    mesh = mesh_labels(_labels())
    for array in (mesh.points, mesh.cells, mesh.cell_data["leaf"], mesh.cell_data["level"]):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = array[1]
    leaf = mesh.cell_data["leaf"]
    mesh.cell_data["leaf"] = leaf.max() - leaf           # the dict's item: a new array
    assert mesh.made is not None and not mesh.made.applies_to(mesh)


def test_renaming_materials_carries_the_recipe_on_purpose():
    mesh = mesh_labels(_labels(), exclude=[0])
    named = mesh.with_material_names({1: "pore", 2: "solid"})
    assert named.recipe is mesh.recipe and named.made.applies_to(named)
    assert named.material_names == {1: "pore", 2: "solid"} and mesh.material_names == {}
    named.info["extra"] = 1
    assert "extra" not in mesh.info                      # its own dicts


def test_refinement_makes_a_new_recipe_not_the_old_one():
    labels = _labels((6, 6, 6), seed=3)
    mesh = mesh_labels(labels, spacing=(2.0, 1.0, 1.0))
    marked = np.zeros(mesh.n_cells, bool)
    marked[::5] = True
    fine = refine_marked(labels, mesh, marked)
    assert fine.recipe is not mesh.recipe
    assert fine.recipe.lattice.refine == mesh.recipe.lattice.refine + 1
    assert fine.recipe.lattice.factors == mesh.recipe.lattice.factors
    assert fine.recipe.adapted == Adapted(steps=1, marked_elements=int(marked.sum()),
                                          split_leaves=fine.recipe.adapted.split_leaves,
                                          from_refine=0)
    assert fine.made is not None and fine.made.applies_to(fine)
    assert mesh.recipe.adapted is None                   # the first mesh is untouched
