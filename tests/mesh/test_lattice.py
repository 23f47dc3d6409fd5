"""Mesh resolution: anisotropy subdivision, interface refinement, size cap, coarsening.

Every property is checked against something the lattice code does not compute itself:
volumes against voxel counts, quality against the template metrics recomputed from the
elements, refinement against the facet groups, sizes against element edges, coarsening
against a per-block bincount.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.mesh.checks._checks import check_mesh
from napari_swa_imesh.mesh.checks._facets import facet_groups
from napari_swa_imesh.mesh.mesher._coarsen import coarsen_labels
from napari_swa_imesh.mesh.mesher._lattice import (
    ASPECT_LIMIT,
    MAX_FACTOR,
    aspect_bounds,
    choose_lattice,
    subdivision_factors,
)
from napari_swa_imesh.mesh.mesher._templates import template_quality
from napari_swa_imesh.mesh.model._memory import estimate_mesh_memory
from napari_swa_imesh.mesh.model._quality import (
    dihedral_angles,
    radius_edge_ratio,
    signed_volumes,
    triangle_angles,
)

#: The physical bound for any spacing at the default limit (issue 22: radius-to-edge <=
#: 1.40, dihedral angles >= 29 deg; the reference's own sqrt(29)/4 and 30 deg hold at
#: max_aspect 1.2, tested below).
RATIO_3D = 1.40
ANGLES_3D = (29.0, 135.0)


def random_labels(rng, d: int, n_max: int = 7, n_labels: int = 3) -> np.ndarray:
    shape = tuple(int(n) for n in rng.integers(2, n_max + 1, size=d))
    smooth = rng.random(shape) < 0.5
    lab = rng.integers(0, n_labels, size=shape)
    # mix blocks and noise so both big leaves and single voxels occur
    lab[smooth] = 1
    return lab.astype(np.uint8)


def random_spacing(rng, d: int) -> tuple[float, ...]:
    aspect = rng.choice([1.0, 1.3, 2.5, 8.0, rng.uniform(1, 8)])
    s = np.ones(d)
    s[rng.integers(d)] = aspect
    s *= rng.uniform(0.2, 3.0, size=d) ** (rng.random() < 0.5)  # sometimes fully random
    return tuple(float(v) for v in s)


def exact_volumes(mesh, lab, exclude=()):
    vol = signed_volumes(mesh.points, mesh.cells)
    voxel = float(np.prod(mesh.spacing))
    for m in np.unique(lab):
        if m in exclude:
            continue
        assert vol[mesh.material == m].sum() == pytest.approx((lab == m).sum() * voxel,
                                                              rel=1e-10)


@pytest.mark.parametrize("seed", range(24))
def test_random_labels_and_spacings_mesh_conforming_exact_and_within_the_physical_bound(seed):
    rng = np.random.default_rng(seed)
    d = 2 + seed % 2
    lab = random_labels(rng, d)
    spacing = random_spacing(rng, d)
    refine = int(rng.integers(0, 2 if d == 3 else 3))
    exclude = (0,) if seed % 3 == 0 and (lab != 0).any() else ()
    mesh = mesh_labels(lab, spacing=spacing, refine=refine, exclude=exclude)
    assert check_mesh(mesh, lab, exclude=exclude).all_passed
    exact_volumes(mesh, lab, exclude)
    lattice = mesh.recipe.lattice.describe()
    assert lattice["residual_aspect"] <= ASPECT_LIMIT + 1e-12
    # quality recomputed from the elements themselves, not the template table
    ratio = radius_edge_ratio(mesh.points, mesh.cells)
    assert ratio.max() <= aspect_bounds(d, lattice["residual_aspect"])["worst_ratio"] + 1e-9
    if d == 3:
        lo, hi = dihedral_angles(mesh.points, mesh.cells)
        assert ratio.max() <= RATIO_3D
        assert ANGLES_3D[0] <= lo.min() and hi.max() <= ANGLES_3D[1]
    else:
        lo, hi = triangle_angles(mesh.points, mesh.cells)
        bound = aspect_bounds(2, ASPECT_LIMIT)
        assert bound["min_angle"] - 1e-9 <= lo.min()
        assert hi.max() <= bound["max_angle"] + 1e-9


def test_extreme_aspect_1_to_8_meets_the_bound_that_stretching_breaks():
    lab = np.zeros((6, 6, 6), np.uint8)
    lab[1:5, 2:5, 1:4] = 1
    lab[3, 3, 3] = 2
    spacing = (8.0, 1.0, 1.0)
    stretched = mesh_labels(lab, spacing=spacing, subdivide=False)
    assert stretched.info["worst_ratio"] > 3            # what the issue measured as wrong
    mesh = mesh_labels(lab, spacing=spacing)
    assert mesh.recipe.lattice.factors == (7, 1, 1)
    assert mesh.info["worst_ratio"] <= RATIO_3D
    assert ANGLES_3D[0] <= mesh.info["min_dihedral"] and mesh.info["max_dihedral"] <= ANGLES_3D[1]
    exact_volumes(mesh, lab)
    assert check_mesh(mesh, lab).all_passed


def test_aspect_bounds_at_the_box_corners_are_the_worst_over_a_grid_of_cell_shapes():
    for d, aspect in ((2, 1.2), (3, 1.2), (3, 1.1)):
        corners = aspect_bounds(d, aspect)
        lo_key, hi_key = ("min_dihedral", "max_dihedral") if d == 3 else ("min_angle", "max_angle")
        for shape in itertools.product(np.linspace(1, aspect, 5), repeat=d):
            q = template_quality(d, shape)
            assert q["quality"].max() <= corners["worst_ratio"] + 1e-12
            assert np.nanmin(q[lo_key]) >= corners["min_angle"] - 1e-9
            assert np.nanmax(q[hi_key]) <= corners["max_angle"] + 1e-9
    # the limit the mesher uses keeps the bound; 1.2 keeps the reference's
    b = aspect_bounds(3, ASPECT_LIMIT)
    assert b["worst_ratio"] <= RATIO_3D and b["min_angle"] >= 29 and b["max_angle"] <= 135
    b = aspect_bounds(3, 1.2)
    assert b["worst_ratio"] <= math.sqrt(29) / 4 and b["min_angle"] >= 30


@pytest.mark.parametrize("spacing", [(2.5, 1.0, 1.0), (1.5, 0.94, 0.94), (4.0, 2.0, 1.0),
                                     (0.3, 1.0), (1.0, 1.0, 1.0), (3.1, 1.7)])
def test_subdivision_factors_are_the_fewest_cells_meeting_the_aspect(spacing):
    got = subdivision_factors(spacing)
    s = np.asarray(spacing)
    assert max(s / got) / min(s / got) <= ASPECT_LIMIT + 1e-12
    # brute force over every factor vector up to 8 per axis
    best = min((math.prod(c) for c in itertools.product(range(1, 9), repeat=len(s))
                if max(s / np.array(c)) / min(s / np.array(c)) <= ASPECT_LIMIT), default=None)
    assert math.prod(got) == best


def test_a_spacing_aspect_beyond_the_factors_is_refused_with_advice():
    with pytest.raises(ValueError, match="resample the image closer to cubic"):
        subdivision_factors((100.0, 1.0))
    assert MAX_FACTOR >= 16


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("refine", [1, 2])
def test_elements_at_interfaces_are_2_to_the_minus_k_voxels(d, refine):
    rng = np.random.default_rng(10 * d + refine)
    lab = np.ones((16,) * d, np.uint8)
    lab[(slice(4, 12),) * d] = 2
    lab[rng.random(lab.shape) < 0.002] = 3
    spacing = tuple(rng.uniform(0.5, 1.0) * np.ones(d))   # cubic voxels, not unit
    mesh = mesh_labels(lab, spacing=spacing, refine=refine)
    cell = np.asarray(spacing) / 2 ** refine
    longest = float(np.linalg.norm(cell))        # a cell's diagonal: its Kuhn edge
    groups = facet_groups(mesh)
    interface = [g for name, g in groups.items() if name.startswith("interface_")]
    assert interface
    for g in interface:
        owners = g.owner
        corners = mesh.points[mesh.cells[owners]]                 # (F, d+1, d)
        edges = corners[:, :, None, :] - corners[:, None, :, :]
        assert np.linalg.norm(edges, axis=-1).max() <= longest + 1e-9
    exact_volumes(mesh, lab)
    assert check_mesh(mesh, lab).all_passed
    # the interior still coarsens: fewer elements than refining everything
    uniform = mesh_labels(lab, spacing=spacing, refine=refine, max_size=longest * 1.0001)
    assert mesh.n_cells < 0.7 * uniform.n_cells


def test_refinement_needs_an_interface_to_act_on():
    lab = np.full((8, 8, 8), 4, np.uint8)
    assert mesh_labels(lab, refine=2).n_cells == mesh_labels(lab).n_cells


def test_excluded_interfaces_are_not_refined_but_their_boundary_with_meshed_ones_is():
    lab = np.zeros((8, 8), np.uint8)
    lab[:, 4:] = 5                                   # 0 | 5, and 0 excluded
    lab[0:2, 0:2] = 7                                # 7 inside the excluded part
    base = mesh_labels(lab, exclude=(0, 7), refine=0)
    refined = mesh_labels(lab, exclude=(0, 7), refine=1)
    assert refined.n_cells > base.n_cells            # the 0|5 side was refined
    # the 0|7 interface lies in excluded material: splitting it would add no elements
    only_excluded = np.zeros((8, 8), np.uint8)
    only_excluded[0:2, 0:2] = 7
    only_excluded[:, 6:] = 5
    a = mesh_labels(only_excluded, exclude=(0, 7), refine=1)
    b = mesh_labels(np.where(only_excluded == 7, 0, only_excluded), exclude=(0,), refine=1)
    assert a.n_cells == b.n_cells


@pytest.mark.parametrize("d", [2, 3])
def test_max_size_caps_every_edge(d):
    lab = np.zeros((16,) * d, np.uint8)
    lab[(slice(4, 11),) * d] = 1
    spacing = (0.7,) * d
    for cap in (2.5, 5.0):
        mesh = mesh_labels(lab, spacing=spacing, max_size=cap)
        corners = mesh.points[mesh.cells]
        edges = np.linalg.norm(corners[:, :, None] - corners[:, None], axis=-1)
        assert edges.max() <= cap + 1e-9
        exact_volumes(mesh, lab)
    assert mesh_labels(lab, spacing=spacing).n_cells < mesh_labels(
        lab, spacing=spacing, max_size=2.5).n_cells


@pytest.mark.parametrize("bad, message", [
    (dict(refine=-1), "refine must be a whole number from 0 to 4"),
    (dict(refine=5), "refine must be a whole number from 0 to 4"),
    (dict(refine=1.5), "refine must be a whole number"),
    (dict(max_size=0.5), "below the longest edge of the smallest element"),
    (dict(max_size=-1), "max_size must be a positive length"),
    (dict(refine=2, max_size=0.4), r"ask for at least 0\.433"),
    (dict(coarsen=6), "coarsen must be a whole number from 0 to 5"),
    (dict(method="delaunay", refine=1), "the delaunay method meshes voxels as they are"),
])
def test_bad_resolution_arguments_say_what_to_pass(bad, message):
    with pytest.raises(ValueError, match=message):
        mesh_labels(np.array([[[1, 2], [2, 1]]] * 2), **bad)


@pytest.mark.parametrize("d", [2, 3])
def test_coarsening_is_the_block_majority_and_reported(d):
    rng = np.random.default_rng(d)
    lab = rng.integers(0, 4, size=(11, 9, 7)[:d]).astype(np.uint16)
    for level in (1, 2):
        out, report = coarsen_labels(lab, level)
        side = 2 ** level
        for block in itertools.product(*(range(0, n, side) for n in lab.shape)):
            sl = tuple(slice(b, b + side) for b in block)
            counts = np.bincount(lab[sl].ravel())
            assert (out[sl] == np.argmax(counts)).all()     # argmax: lowest label on a tie
        for m, before in report["voxels_before"].items():
            after = int((out == m).sum())
            assert report["voxels_after"][m] == after
            assert report["relative_change"][m] == pytest.approx(after / before - 1)
        assert report["changed_voxels"] == int((out != lab).sum())
        assert out.dtype == lab.dtype and out.shape == lab.shape


def test_coarsened_mesh_has_big_leaves_and_names_a_lost_material():
    lab = np.zeros((32, 32, 32), np.uint8)
    lab[4:28, 4:28, 4:28] = 1
    rough = np.random.default_rng(0).random(lab.shape) < 0.01  # voxel-scale roughness
    lab[rough] = 1 - lab[rough]
    lab[10, 10, 10] = 2                                       # a single voxel
    fine = mesh_labels(lab, material_names={2: "speck"})
    with pytest.warns(UserWarning, match=r"removed material\(s\) 2 \(speck\) entirely"):
        coarse = mesh_labels(lab, coarsen=2, material_names={2: "speck"})
    assert coarse.n_cells < fine.n_cells / 4
    assert coarse.info["coarsen"]["lost"] == [2]
    report = coarse.info["coarsen"]
    assert report["relative_change"][1] == pytest.approx(
        (coarsen_labels(lab, 2)[0] == 1).sum() / (lab == 1).sum() - 1)
    assert abs(report["relative_change"][1]) < 0.02
    assert check_mesh(coarse, coarsen_labels(lab, 2)[0]).all_passed
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh_labels(lab, coarsen=0)


def test_memory_estimate_grows_with_the_lattice():
    base = estimate_mesh_memory((64, 64, 64), np.uint8, n_boundary=5000)
    assert estimate_mesh_memory((64, 64, 64), np.uint8, n_boundary=5000,
                                cells_per_voxel=(1, 1, 1)) == base
    finer = estimate_mesh_memory((64, 64, 64), np.uint8, n_boundary=5000,
                                 cells_per_voxel=(2, 2, 2))
    assert finer > 1.3 * base


def test_choose_lattice_describes_itself():
    # 2.5/2 = 1.25 is within the default limit, so two cells along the first axis
    lat = choose_lattice((2.5, 1.0, 1.0), refine=1)
    info = lat.describe()
    assert info["factors"] == [2, 1, 1] and info["cells_per_voxel"] == [4, 2, 2]
    assert info["step"] == pytest.approx([2.5 / 4, 0.5, 0.5])
    assert info["max_aspect"] == ASPECT_LIMIT == 1.25
    assert info["bounds"]["worst_ratio"] == pytest.approx(aspect_bounds(3, 1.25)["worst_ratio"])
