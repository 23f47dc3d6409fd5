"""Mesh.to_pyvista: VTK sees the same elements, volumes and cell data as the mesh."""

import sys

import numpy as np
import pytest
from imesh_cases import blobs

from napari_swa_imesh.mesh import mesh_labels, signed_volumes, write_mesh
from napari_swa_imesh.mesh.formats._common import export_points

pv = pytest.importorskip("pyvista")


def _mesh(ndim, spacing):
    shape = (10, 12, 9)[:ndim]
    return mesh_labels(blobs(shape, 3, seed=ndim), spacing=spacing, exclude=[0],
                       material_names={1: "a"})


@pytest.mark.parametrize("ndim,spacing", [(2, (1.0, 1.0)), (2, (0.5, 2.0)),
                                          (3, (1.0, 1.0, 1.0)), (3, (2.0, 1.0, 0.5))])
def test_vtk_measures_our_volumes_and_reads_our_cell_data(ndim, spacing):
    mesh = _mesh(ndim, spacing)
    grid = mesh.to_pyvista()
    assert grid.n_cells == mesh.n_cells and grid.n_points == len(mesh.points)
    kind = pv.CellType.TETRA if ndim == 3 else pv.CellType.TRIANGLE
    assert (grid.celltypes == kind).all()
    np.testing.assert_array_equal(grid.points[:, :ndim], export_points(mesh))
    if ndim == 2:
        assert (grid.points[:, 2] == 0).all()
    # VTK's own cell sizes (signed: an inverted cell would come out negative)
    name = "Volume" if ndim == 3 else "Area"
    sizes = grid.compute_cell_sizes(length=False, area=ndim == 2, volume=ndim == 3)
    ours = signed_volumes(mesh.points, mesh.cells)
    assert (ours > 0).all()
    np.testing.assert_allclose(sizes.cell_data[name], ours, rtol=1e-12)
    # their sum is the meshed part of the image box
    labels = blobs((10, 12, 9)[:ndim], 3, seed=ndim)
    assert sizes.cell_data[name].sum() == pytest.approx(
        np.count_nonzero(labels) * np.prod(spacing))
    np.testing.assert_array_equal(grid.cell_data["material"], mesh.material)
    assert set(grid.cell_data.keys()) == {"material", *mesh.cell_data}
    for key, values in mesh.cell_data.items():
        np.testing.assert_array_equal(grid.cell_data[key], values)


def test_the_grid_is_what_paraview_reads_from_our_vtu(tmp_path):
    mesh = _mesh(3, (2.0, 1.0, 0.5))
    path = write_mesh(mesh, tmp_path / "m.vtu")[0]          # then its _facets.vtu
    read, grid = pv.read(path), mesh.to_pyvista()
    np.testing.assert_array_equal(read.points, grid.points)
    np.testing.assert_array_equal(read.cell_connectivity, grid.cell_connectivity)
    np.testing.assert_array_equal(read.cell_data["quality"], grid.cell_data["quality"])


def test_original_point_ids_lead_back_to_napari_coordinates():
    mesh = _mesh(3, (2.0, 1.0, 0.5))
    grid = mesh.to_pyvista()
    surface = grid.extract_surface(algorithm=None)
    ids = surface.point_data["vtkOriginalPointIds"]
    # the (plane, row, column) points napari draws are the grid's points, axes reversed
    np.testing.assert_array_equal(mesh.points[ids][:, ::-1], surface.points)
    lo, hi = mesh.image_box()
    np.testing.assert_allclose(surface.bounds[::2], lo[::-1])
    np.testing.assert_allclose(surface.bounds[1::2], hi[::-1])


def test_without_pyvista_the_bridge_says_how_to_install_it(monkeypatch):
    mesh = _mesh(2, (1.0, 1.0))
    monkeypatch.setitem(sys.modules, "pyvista", None)
    with pytest.raises(ImportError, match="pip install pyvista"):
        mesh.to_pyvista()


def test_the_mesh_is_not_changed():
    mesh = _mesh(3, (2.0, 1.0, 0.5))
    before = mesh.points.copy(), mesh.cells.copy()
    mesh.to_pyvista()
    np.testing.assert_array_equal(mesh.points, before[0])
    np.testing.assert_array_equal(mesh.cells, before[1])


@pytest.mark.parametrize("flip", [1.0, -1.0])
def test_a_world_placed_mesh_is_in_its_world_frame_with_positive_cells(flip):
    # a NIfTI-like placement: axes not reversed (so possibly mirrored), scaled, turned
    mesh = _mesh(3, (2.0, 1.0, 0.5))
    angle = 0.3
    turn = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                     [0, 0, flip]])
    world = np.eye(4)
    world[:3, :3], world[:3, 3] = 1.5 * turn, (10.0, -4.0, 2.0)
    mesh.world = world
    grid = mesh.to_pyvista()
    np.testing.assert_allclose(grid.points, export_points(mesh))
    sizes = grid.compute_cell_sizes(length=False, area=False).cell_data["Volume"]
    np.testing.assert_allclose(sizes, signed_volumes(mesh.points, mesh.cells) * 1.5 ** 3,
                               rtol=1e-9)
