"""What napari sees of the plugin: samples, menus, dock widgets, reader; the mesh surface."""

from collections import Counter

import numpy as np
import pytest

from napari_swa_imesh._napari._surface import mesh_surface, shown_faces
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.mesh._imesh import mesh_labels

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
    assert f"{PLUGIN}.workflow_widget" in segment
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


def _brute_force_faces(cells, material):
    """Faces of tetrahedra bounding the mesh or two materials, by counting (small meshes)."""
    owners = {}
    for i, tet in enumerate(cells.tolist()):
        for k in range(4):
            owners.setdefault(tuple(sorted(tet[:k] + tet[k + 1:])), []).append(i)
    return {f for f, o in owners.items()
            if len(o) == 1 or material[o[0]] != material[o[1]]}


@pytest.mark.parametrize("seed", [0, 1])
def test_shown_faces_are_the_boundary_and_the_interfaces(seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(1, 4, (6, 7, 5))
    mesh = mesh_labels(labels, spacing=(2.0, 1.0, 1.0), exclude=[3])
    faces, owners = shown_faces(mesh.cells, mesh.material)
    keys = [tuple(sorted(f)) for f in faces.tolist()]
    assert Counter(keys).most_common(1)[0][1] == 1
    assert set(keys) == _brute_force_faces(mesh.cells, mesh.material)
    # each face is drawn from its first owner, as that element oriented it (outward)
    for f, (a, _) in zip(faces.tolist(), owners.tolist()):
        assert set(f) < set(mesh.cells[a].tolist())


def test_surface_gives_each_triangle_its_own_vertices_and_value():
    labels = np.array([[1, 1, 2], [1, 2, 2]])
    mesh = mesh_labels(labels)
    surface = mesh_surface(mesh)
    assert surface["n_faces"] == mesh.n_cells
    assert surface["vertices"].shape == (3 * mesh.n_cells, 2)
    np.testing.assert_array_equal(surface["triangles"].ravel(), np.arange(3 * mesh.n_cells))
    np.testing.assert_allclose(surface["vertices"].reshape(-1, 3, 2), mesh.points[mesh.cells])
    np.testing.assert_array_equal(surface["material"], np.repeat(mesh.material, 3))


@pytest.mark.parametrize("suffix", [".vtu", ".vtk", ".msh", ".xdmf", ".inp", ".node"])
@pytest.mark.parametrize("ndim", [2, 3])
def test_writer_writes_every_format_of_the_mesh_engine(tmp_path, suffix, ndim):
    from napari_swa_imesh._napari._layers import MESH_KEY
    from napari_swa_imesh._napari._writer import write_mesh_layer
    from napari_swa_imesh.mesh._export import read_mesh

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
