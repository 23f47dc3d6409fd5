"""Meshes placed by an image's affine: every file holds world coordinates (NIfTI convention).

The reference is nibabel's own ``apply_affine`` on voxel-corner indices (voxel centres at
integer indices, so corner c of the mesher is index c - 0.5), never our world matrix.
"""

from __future__ import annotations

import warnings

import meshio
import numpy as np
import pytest

from napari_swa_imesh.mesh import (
    Mesh,
    mesh_labels,
    radius_edge_ratio,
    signed_volumes,
    to_meshio,
    world_from_affine,
    write_mesh,
)
from napari_swa_imesh.mesh.formats._common import export_points, export_vectors

apply_affine = pytest.importorskip("nibabel.affines").apply_affine

SIZES = (0.7, 1.3, 2.1)
ORIGIN = (-40.0, 12.5, 7.0)


def rotation(ndim: int, *, flip: bool, seed: int = 0) -> np.ndarray:
    """A random oblique rotation (flip: a reflection, determinant -1)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(ndim, ndim)))
    q = q * np.sign(np.diag(r))
    if (np.linalg.det(q) < 0) != flip:
        q[:, 0] = -q[:, 0]
    return q


def oblique_affine(ndim: int = 3, *, flip: bool = True) -> np.ndarray:
    """Index-to-world affine: oblique, flipped when asked, anisotropic, with an origin."""
    affine = np.eye(ndim + 1)
    affine[:ndim, :ndim] = rotation(ndim, flip=flip) @ np.diag(SIZES[:ndim])
    affine[:ndim, ndim] = ORIGIN[:ndim]
    return affine


def labels_3d() -> np.ndarray:
    rng = np.random.default_rng(7)
    labels = np.ones((7, 6, 9), np.uint8)
    labels[1:6, 2:5, 3:8] = 2
    labels[rng.random(labels.shape) < 0.08] = 3
    return labels


def labels_2d() -> np.ndarray:
    labels = np.ones((9, 12), np.uint8)
    labels[2:7, 3:10] = 2
    labels[4, 5] = 3
    return labels


def corner_index(mesh: Mesh) -> np.ndarray:
    """Voxel-corner index of each point in the image frame (where the mesher put it)."""
    return mesh.points / np.asarray(mesh.spacing)


@pytest.mark.parametrize("flip", [True, False])
@pytest.mark.parametrize("ndim", [2, 3])
def test_vertices_are_nibabel_world_positions_of_voxel_corners(tmp_path, ndim, flip):
    affine = oblique_affine(ndim, flip=flip)
    labels = labels_3d() if ndim == 3 else labels_2d()
    mesh = mesh_labels(labels, affine=affine)
    np.testing.assert_allclose(mesh.spacing, SIZES[:ndim])
    written = write_mesh(mesh, tmp_path / "m.vtu")[0]
    back = meshio.read(written)
    points = back.points[:, :ndim]
    corner = corner_index(mesh)
    on_corner = np.all(np.abs(corner - np.round(corner)) < 1e-9, axis=1)
    # anisotropic voxels are subdivided: many vertices are lattice points inside voxels
    assert on_corner.mean() > 0.1
    expected = apply_affine(affine, np.round(corner[on_corner]) - 0.5)
    np.testing.assert_allclose(points[on_corner], expected, atol=1e-9)
    # the rest (lattice points, leaf centres) follow the same map
    np.testing.assert_allclose(points, apply_affine(affine, corner - 0.5), atol=1e-9)


@pytest.mark.parametrize("flip", [True, False])
@pytest.mark.parametrize("ndim", [2, 3])
def test_each_material_keeps_its_world_volume(tmp_path, ndim, flip):
    affine = oblique_affine(ndim, flip=flip)
    labels = labels_3d() if ndim == 3 else labels_2d()
    back = meshio.read(write_mesh(mesh_labels(labels, affine=affine), tmp_path / "m.vtu")[0])
    cells = back.cells[0].data
    volumes = signed_volumes(back.points[:, :ndim], cells)
    assert (volumes > 0).all()
    voxel = abs(np.linalg.det(affine[:ndim, :ndim]))
    material = back.cell_data["material"][0]
    for value in np.unique(labels):
        assert volumes[material == value].sum() == pytest.approx(
            np.count_nonzero(labels == value) * voxel, rel=1e-12)


@pytest.mark.parametrize("suffix", [".vtu", ".vtk", ".msh", ".xdmf", ".inp"])
def test_every_format_holds_world_points_positively_oriented(tmp_path, suffix):
    affine = oblique_affine(3, flip=True)
    assert np.linalg.det(affine) < 0
    mesh = mesh_labels(labels_3d(), affine=affine, exclude=[3])
    path = write_mesh(mesh, tmp_path / f"m{suffix}")[0]
    back = meshio.read(path)
    tetra = np.concatenate([b.data for b in back.cells if b.type == "tetra"])
    assert len(tetra) == mesh.n_cells
    assert (signed_volumes(back.points, tetra) > 0).all()
    np.testing.assert_allclose(np.unique(np.round(back.points, 9), axis=0),
                               np.unique(np.round(export_points(mesh), 9), axis=0))
    # and the points are the world positions, not the image frame
    lo = back.points.min(axis=0)
    assert not np.allclose(lo, 0.0)


def test_triangle_tetgen_files_hold_world_points(tmp_path):
    from napari_swa_imesh.mesh.formats._triangle_tetgen import read_node_ele

    affine = oblique_affine(3, flip=True)
    mesh = mesh_labels(labels_3d(), affine=affine)
    write_mesh(mesh, tmp_path / "m.node")
    points, cells, _ = read_node_ele(tmp_path / "m.node")
    assert (signed_volumes(points, cells) > 0).all()
    np.testing.assert_allclose(points, apply_affine(affine, corner_index(mesh) - 0.5),
                               atol=1e-9)


def test_quality_in_the_file_is_the_quality_the_mesh_records(tmp_path):
    # a similarity leaves radius-to-edge ratios unchanged: stored points are scaled by the
    # voxel sizes, and what remains is a rotation with a flip
    mesh = mesh_labels(labels_3d(), affine=oblique_affine(3, flip=True))
    m = to_meshio(mesh)
    np.testing.assert_allclose(radius_edge_ratio(m.points, m.cells[0].data), mesh.quality,
                               rtol=1e-9)


def test_image_frame_is_kept_inside_the_mesh():
    labels = labels_3d()
    placed = mesh_labels(labels, affine=oblique_affine(3))
    np.testing.assert_allclose(placed.spacing, SIZES, rtol=1e-15)
    plain = mesh_labels(labels, spacing=placed.spacing)
    np.testing.assert_array_equal(placed.points, plain.points)
    np.testing.assert_array_equal(placed.cells, plain.cells)
    lo, hi = placed.image_box()
    np.testing.assert_allclose(hi, np.multiply(labels.shape, SIZES), rtol=1e-15)
    assert plain.world is None
    np.testing.assert_array_equal(export_points(plain), plain.points[:, ::-1])


def test_world_is_an_affine_of_the_points_dimension():
    spacing, world = world_from_affine(np.diag([2.0, 3.0, 1.0]), 2)
    assert spacing == (2.0, 3.0)
    np.testing.assert_array_equal(world, [[1, 0, -1], [0, 1, -1.5], [0, 0, 1]])
    # a 2-D image in a 3-D world (NIfTI stores 4 x 4): the plane of constant z
    spacing, world = world_from_affine(np.diag([2.0, 3.0, 5.0, 1.0]), 2)
    assert spacing == (2.0, 3.0) and world.shape == (3, 3)


@pytest.mark.parametrize("affine,ndim,match", [
    (np.diag([1.0, 0.0, 1.0, 1.0]), 3, "singular"),
    ([[1, 2, 0, 0], [2, 4, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], 3, "singular"),
    (np.eye(3), 3, r"must be a \(4, 4\) matrix of numbers for a 3-D image"),
    (np.eye(5), 2, r"must be a \(3, 3\) or \(4, 4\) matrix"),
    (np.eye(5), 3, r"got float64 of shape \(5, 5\)"),
    (np.diag([1.0, 1.0, np.nan, 1.0]), 3, "finite"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0.5, 0, 1, 0], [0, 0, 0, 1]], 2, "out of the world's x-y"),
    ([[1, 0, 0], [0, 1, 0], [1, 0, 1]], 2, "last row"),
])
def test_bad_affines_are_refused(affine, ndim, match):
    with pytest.raises(ValueError, match=match):
        world_from_affine(affine, ndim)


def test_shear_is_placed_exactly_with_a_warning(tmp_path):
    affine = np.array([[1.0, 0.5, 0, 3], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]])
    with pytest.warns(UserWarning, match=r"shears the voxels \(two voxel axes 63.4 degrees"):
        mesh = mesh_labels(labels_3d(), affine=affine)
    back = meshio.read(write_mesh(mesh, tmp_path / "m.vtu")[0])
    np.testing.assert_allclose(back.points, apply_affine(affine, corner_index(mesh) - 0.5),
                               atol=1e-9)
    assert radius_edge_ratio(back.points, back.cells[0].data).max() > mesh.quality.max()


def test_float32_rounding_of_a_rotation_is_no_shear():
    affine = oblique_affine(3).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        world_from_affine(affine, 3)


def test_spacing_and_affine_together_are_refused():
    with pytest.raises(ValueError, match="spacing or affine, not both"):
        mesh_labels(labels_2d(), spacing=2.0, affine=np.eye(3))


def test_vectors_turn_with_the_points():
    mesh = mesh_labels(labels_3d(), affine=oblique_affine(3))
    v = np.random.default_rng(1).normal(size=(5, 3))
    np.testing.assert_allclose(export_vectors(mesh, v), v @ mesh.world[:3, :3].T)
    # a vector between two points turns like their difference
    p = mesh.points[:2]
    np.testing.assert_allclose(export_vectors(mesh, p[1:] - p[:1]),
                               export_points(mesh)[1:2] - export_points(mesh)[:1])
    plain = mesh_labels(labels_3d())
    np.testing.assert_array_equal(export_vectors(plain, v), v[:, ::-1])


@pytest.mark.parametrize("world,match", [
    (np.eye(4), r"\(3, 3\) matrix"),
    ([[1, 0, 0], [0, 1, 0], [0, 1, 1]], "last row"),
    ([[1, 2, 0], [2, 4, 0], [0, 0, 1]], "singular"),
])
def test_mesh_refuses_a_bad_world(world, match):
    with pytest.raises(ValueError, match=match):
        Mesh([[0, 0], [0, 1], [1, 0]], [[0, 2, 1]], [1], world=world)
