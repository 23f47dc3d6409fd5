"""TIFF images open with their voxel spacing, and meshes open back as Surfaces coloured by
material (issue 23, sec. 4-5), through napari's own viewer.open."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._layers import MESH_KEY
from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._simulate_widget import SimulateWidget
from napari_swa_imesh.mesh import mesh_labels, write_mesh

PLUGIN = "napari-swa-imesh"
SPACING = (2.0, 0.5, 0.25)          # plane, row, column (ImageJ: spacing, 1/yres, 1/xres)


def two_materials(shape=(6, 8, 12)) -> np.ndarray:
    labels = np.ones(shape, np.uint8)
    labels[:, :, shape[2] // 2:] = 2
    labels[2:4, 3:6, 2:4] = 3
    return labels


def write_imagej(path, data, spacing=SPACING):
    tifffile.imwrite(path, data, imagej=True, resolution=(1 / spacing[2], 1 / spacing[1]),
                     metadata={"spacing": spacing[0], "unit": "um", "axes": "ZYX"})


def test_tiff_opens_with_its_spacing_and_meshes_in_physical_units(make_napari_viewer, qtbot,
                                                                   tmp_path):
    labels = two_materials()
    write_imagej(tmp_path / "phantom_labels.tif", labels)
    viewer = make_napari_viewer()
    (layer,) = viewer.open(tmp_path / "phantom_labels.tif", plugin=PLUGIN)
    assert type(layer).__name__ == "Labels"
    np.testing.assert_array_equal(layer.data, labels)
    np.testing.assert_allclose(layer.scale, SPACING)

    widget = MeshWidget(viewer)
    widget.select_labels(layer)
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    mesh = widget.mesh
    np.testing.assert_allclose(mesh.points.min(axis=0), 0)
    np.testing.assert_allclose(mesh.points.max(axis=0), np.array(labels.shape) * SPACING)
    np.testing.assert_allclose(mesh.spacing, SPACING)
    volume = np.abs(np.linalg.det(np.stack([
        mesh.points[mesh.cells[:, i]] - mesh.points[mesh.cells[:, 0]] for i in (1, 2, 3)],
        axis=1))).sum() / 6
    assert volume == pytest.approx(np.prod(np.array(labels.shape) * SPACING))
    # the simulation runs on that mesh, in the same physical box
    simulate = SimulateWidget(viewer)
    assert simulate.mesh_combo.value is widget.surface_layer
    simulate.run()
    wait_idle(qtbot, simulate, timeout=120_000)
    assert simulate.result is not None
    np.testing.assert_allclose(simulate.result.mesh.points.max(axis=0),
                               np.array(labels.shape) * SPACING)


def test_a_grey_tiff_opens_as_an_image_with_its_spacing(make_napari_viewer, tmp_path):
    data = np.random.default_rng(0).normal(size=(4, 9, 10)).astype(np.float32)
    write_imagej(tmp_path / "scan.tif", data)
    (layer,) = make_napari_viewer().open(tmp_path / "scan.tif", plugin=PLUGIN)
    assert type(layer).__name__ == "Image"
    np.testing.assert_allclose(layer.scale, SPACING)


@pytest.mark.parametrize("suffix", [".vtu", ".msh"])
def test_a_saved_mesh_opens_back_coloured_by_material(make_napari_viewer, tmp_path, suffix):
    labels = two_materials()
    mesh = mesh_labels(labels, spacing=SPACING, material_names={1: "a", 2: "b", 3: "c"})
    path = tmp_path / f"mesh{suffix}"
    write_mesh(mesh, path)
    viewer = make_napari_viewer()
    (layer,) = viewer.open(path, plugin=PLUGIN)
    assert type(layer).__name__ == "Surface"
    back = layer.metadata[MESH_KEY]
    assert back.cells.shape == mesh.cells.shape           # the tetrahedra, not the faces
    np.testing.assert_allclose(np.sort(back.points, axis=0), np.sort(mesh.points, axis=0))
    vertices, triangles, values = layer.data
    # faces: boundary and interfaces only, each coloured by the material of its element
    assert 0 < len(triangles) < 4 * mesh.n_cells
    # (an interface face takes the material of one of its two elements, as in the Mesh tab)
    shown = set(np.unique(values))
    assert {1.0, 2.0} <= shown <= {1.0, 2.0, 3.0}
    colors = layer.vertex_colors
    assert colors.shape == (len(vertices), 4)
    from napari.utils.colormaps.standardize_color import transform_color

    from napari_swa_imesh._napari._layers import default_color

    for m in shown:
        np.testing.assert_allclose(colors[values == m], np.broadcast_to(
            transform_color(default_color(int(m)))[0], colors[values == m].shape))
    if suffix == ".msh":       # Gmsh physical groups carry the names (.vtu does not)
        assert back.material_names == {1: "a", 2: "b", 3: "c"}
    # the Simulate tab can run on it
    assert SimulateWidget(viewer).mesh_combo.value is layer


def test_write_read_round_trip_through_napari(make_napari_viewer, qtbot, tmp_path):
    """napari's Save (the writer) then viewer.open (the reader) give the same mesh."""
    viewer = make_napari_viewer()
    labels = viewer.add_labels(two_materials(), scale=SPACING, name="labels")
    widget = MeshWidget(viewer)
    widget.select_labels(labels)
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    viewer.layers.selection = {widget.surface_layer}
    viewer.layers.save(str(tmp_path / "saved.vtu"), selected=True, plugin=PLUGIN)
    (layer,) = viewer.open(tmp_path / "saved.vtu", plugin=PLUGIN)
    back, mesh = layer.metadata[MESH_KEY], widget.mesh
    assert back.n_cells == mesh.n_cells
    np.testing.assert_array_equal(np.bincount(back.material), np.bincount(mesh.material))
    np.testing.assert_allclose(back.points.max(axis=0), mesh.points.max(axis=0))


def test_the_open_paths_the_readme_teaches(make_napari_viewer, tmp_path):
    """napari 0.9's viewer.open defaults to its own reader (plugin="napari"), which fails on
    .nii.gz and drops a TIFF's spacing; the README teaches plugin="napari-swa-imesh", or a
    reader preference once, after which plugin=None and File > Open use this plugin."""
    from napari.settings import get_settings

    write_imagej(tmp_path / "scan.tif", np.zeros((3, 4, 5), np.float32))
    viewer = make_napari_viewer()
    (plain,) = viewer.open(tmp_path / "scan.tif")
    assert tuple(plain.scale) == (1.0, 1.0, 1.0)          # napari's reader: no spacing
    (layer,) = viewer.open(tmp_path / "scan.tif", plugin=PLUGIN)
    np.testing.assert_allclose(layer.scale, SPACING)
    settings = get_settings().plugins
    before = dict(settings.extension2reader)
    try:
        settings.extension2reader = {**before, "*.tif": PLUGIN}
        (preferred,) = viewer.open(tmp_path / "scan.tif", plugin=None)
        np.testing.assert_allclose(preferred.scale, SPACING)
    finally:
        settings.extension2reader = before
