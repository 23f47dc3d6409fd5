"""What napari sees of the plugin: samples, menus, dock widgets, reader.

(The faces drawn for a mesh are tested headless in tests/mesh/test_surface.py.)"""

import numpy as np
import pytest

from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.mesh import mesh_labels, mesh_surface

PLUGIN = "napari-swa-imesh"


def test_sample_data_open_with_truth_and_spacing(make_napari_viewer):
    viewer = make_napari_viewer()
    viewer.open_sample(PLUGIN, "texture_mosaic")
    image, truth = viewer.layers
    assert image.data.shape == truth.data.shape == (256, 256)
    assert type(truth).__name__ == "Labels" and set(np.unique(truth.data)) == {1, 2}
    viewer.open_sample(PLUGIN, "tissue_phantom")
    phantom, phantom_truth = viewer.layers[2:]
    assert phantom.data.ndim == 3 and phantom.data.dtype == np.float32
    assert tuple(phantom.scale) == tuple(phantom_truth.scale) == (2.0, 1.0, 1.0)
    assert phantom_truth.metadata["material_names"][2] == "grey matter"


def test_widgets_in_the_plugins_menu_and_the_workflow_under_layers_segment(make_napari_viewer):
    from napari._app_model import get_app_model

    viewer = make_napari_viewer()
    app = get_app_model()

    def commands(menu_id):
        out = set()
        for item in app.menus.get_menu(menu_id):
            if hasattr(item, "command"):
                out.add(item.command.id)
            elif hasattr(item, "submenu"):
                out |= commands(item.submenu)
        return out

    segment = commands("napari/layers/segment")
    assert {f"{PLUGIN}.{w}_widget" for w in ("workflow", "samples", "res", "classify")} \
        <= segment
    assert {f"{PLUGIN}.mesh_widget", f"{PLUGIN}.simulate_widget"} <= commands(
        "napari/layers/measure")
    # and they are in the window's own Layers menu, where a user looks
    layers = next(a.menu() for a in viewer.window._qt_window.menuBar().actions()
                  if a.text().replace("&", "") == "Layers")
    shown = {(sub.text(), a.text()) for sub in layers.actions() if sub.menu()
             for a in sub.menu().actions()}
    assert {("Segment", "Segment and mesh (SWA-IMESH)"), ("Segment", "Classify (SWA) (SWA-IMESH)"),
            ("Measure", "Mesh (IMESH) (SWA-IMESH)"),
            ("Measure", "Simulate (k_eff) (SWA-IMESH)")} <= shown
    plugins = commands("napari/plugins")
    assert {f"{PLUGIN}.{w}_widget" for w in ("workflow", "samples", "res", "classify",
                                            "mesh", "simulate")} <= plugins
    _, widget = viewer.window.add_plugin_dock_widget(PLUGIN, "Segment and mesh")
    assert isinstance(widget, WorkflowWidget)
    assert [widget.tabs.tabText(i) for i in range(widget.tabs.count())] == [
        "Samples", "RES", "Classify", "Mesh", "Simulate"]


def test_nifti_reader_keeps_the_voxel_spacing(make_napari_viewer, tmp_path):
    nib = pytest.importorskip("nibabel")
    data = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    image = nib.Nifti1Image(data, affine=np.diag([2.0, 0.5, 1.5, 1.0]))
    nib.save(image, tmp_path / "vol.nii.gz")
    viewer = make_napari_viewer()
    (layer,) = viewer.open(tmp_path / "vol.nii.gz", plugin=PLUGIN)
    assert layer.name == "vol"
    np.testing.assert_array_equal(layer.data, data)
    assert tuple(layer.scale) == (2.0, 0.5, 1.5)


@pytest.mark.parametrize("suffix", [".vtu", ".vtk", ".msh", ".xdmf", ".inp", ".node"])
@pytest.mark.parametrize("ndim", [2, 3])
def test_writer_writes_every_format_of_the_mesh_engine(tmp_path, suffix, ndim):
    from napari_swa_imesh._napari._layers import MESH_KEY
    from napari_swa_imesh._napari._writer import write_mesh_layer
    from napari_swa_imesh.mesh.formats._export import read_mesh

    rng = np.random.default_rng(ndim)
    mesh = mesh_labels(rng.integers(1, 3, (4,) * ndim), spacing=(2.0,) + (1.0,) * (ndim - 1))
    surface = mesh_surface(mesh)
    written = write_mesh_layer(str(tmp_path / f"m{suffix}"),
                               (surface["vertices"], surface["triangles"]),
                               {"name": "m", "metadata": {MESH_KEY: mesh}})
    assert str(tmp_path / f"m{suffix}") in written
    back = read_mesh(tmp_path / f"m{suffix}")
    assert back.cells.shape == mesh.cells.shape         # elements, not the drawn faces
    np.testing.assert_allclose(np.sort(back.points, axis=0), np.sort(mesh.points, axis=0))
    np.testing.assert_array_equal(np.sort(back.material), np.sort(mesh.material))
