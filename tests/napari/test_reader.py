"""The NIfTI reader: layers placed by the file's affine, label volumes as Labels, and the
mesh of a NIfTI labels layer drawn (and written) where the voxels are."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._reader import looks_like_labels

nib = pytest.importorskip("nibabel")
apply_affine = nib.affines.apply_affine
PLUGIN = "napari-swa-imesh"


def oblique_flipped_affine() -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(4).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) > 0:
        q[:, 2] = -q[:, 2]
    affine = np.eye(4)
    affine[:3, :3] = q @ np.diag([0.9, 1.6, 2.2])
    affine[:3, 3] = [-20.0, 8.0, 3.5]
    return affine


def save(path, data, affine=None) -> np.ndarray:
    nib.save(nib.Nifti1Image(data, oblique_flipped_affine() if affine is None else affine),
             str(path))
    return nib.load(str(path)).affine


def nearest_axes(affine) -> np.ndarray:
    """NIfTI world axis nearest to each array axis, by brute force over permutations."""
    from itertools import permutations

    unit = np.abs(affine[:-1, :-1] / np.linalg.norm(affine[:-1, :-1], axis=0))
    return np.array(max(permutations(range(len(unit))),
                        key=lambda p: sum(unit[p[a], a] for a in range(len(unit)))))


def napari_world(affine, index) -> np.ndarray:
    """napari world of voxel `index`: the NIfTI world, axes in the order of the nearest."""
    return apply_affine(affine, index)[..., nearest_axes(affine)]


def test_image_layer_lies_where_the_affine_puts_the_voxels(make_napari_viewer, tmp_path):
    data = np.random.default_rng(0).normal(size=(5, 6, 7)).astype(np.float32)
    affine = save(tmp_path / "t1.nii.gz", data)
    viewer = make_napari_viewer()
    (layer,) = viewer.open(tmp_path / "t1.nii.gz", plugin=PLUGIN)
    assert type(layer).__name__ == "Image" and layer.name == "t1"
    np.testing.assert_array_equal(layer.data, data)
    np.testing.assert_allclose(layer.scale, np.linalg.norm(affine[:3, :3], axis=0))
    for index in ([0, 0, 0], [4, 5, 6], [2, 0, 3]):
        np.testing.assert_allclose(layer.data_to_world(index), napari_world(affine, index),
                                   atol=1e-9)


def test_axis_swapped_file_gets_a_diagonal_napari_affine(make_napari_viewer, tmp_path):
    # stored as (z, y, x) with x flipped: a plain swap of the world axes would make the
    # affine singular on the two displayed axes, which napari cannot draw
    affine = np.array([[0.0, 0, -0.5, 10], [0, 2, 0, -4], [3, 0, 0, 1], [0, 0, 0, 1]])
    save(tmp_path / "zyx.nii.gz", np.zeros((4, 5, 6), np.float32), affine)
    (layer,) = make_napari_viewer().open(tmp_path / "zyx.nii.gz", plugin=PLUGIN)
    matrix = layer.affine.affine_matrix[:3, :3]
    np.testing.assert_allclose(matrix, np.diag([1.0, 1.0, -1.0]))
    np.testing.assert_allclose(layer.scale, (3.0, 2.0, 0.5))
    np.testing.assert_allclose(layer.data_to_world([3, 4, 5]),
                               apply_affine(affine, [3, 4, 5])[[2, 1, 0]], atol=1e-9)


def test_2d_image_in_a_plane_of_constant_z(make_napari_viewer, tmp_path):
    affine = np.array([[0.0, -2, 0, 5], [3, 0, 0, 1], [0, 0, 1, 7], [0, 0, 0, 1]])
    save(tmp_path / "slice.nii", np.ones((4, 5), np.float32) * np.arange(5), affine)
    (layer,) = make_napari_viewer().open(tmp_path / "slice.nii", plugin=PLUGIN)
    assert layer.ndim == 2
    # array axis 0 runs along world y, axis 1 along -x: napari world is (y, x)
    np.testing.assert_allclose(layer.data_to_world([3, 4]),
                               apply_affine(affine, [3, 4, 0])[[1, 0]], atol=1e-9)


@pytest.mark.parametrize("name,data,labels", [
    ("vol", np.random.default_rng(1).integers(0, 4, (6, 6, 6)).astype(np.int16), True),
    ("vol", np.random.default_rng(2).integers(0, 256, (6, 6, 6)).astype(np.uint8), False),
    ("brain_seg", np.random.default_rng(3).integers(0, 300, (6, 6, 6)).astype(np.int32),
     True),
    ("vol", np.random.default_rng(4).integers(0, 3, (6, 6, 6)).astype(np.float32), True),
    ("mask", np.random.default_rng(5).random((6, 6, 6)).astype(np.float32), False),
])
def test_label_volumes_open_as_labels(make_napari_viewer, tmp_path, name, data, labels):
    assert looks_like_labels(data, name) is labels
    save(tmp_path / f"{name}.nii.gz", data)
    (layer,) = make_napari_viewer().open(tmp_path / f"{name}.nii.gz", plugin=PLUGIN)
    assert type(layer).__name__ == ("Labels" if labels else "Image")
    np.testing.assert_array_equal(layer.data, data)
    if labels:
        assert layer.data.dtype.kind in "iu"


def test_opens_without_naming_the_plugin_once_it_is_the_preferred_reader(
        make_napari_viewer, tmp_path, monkeypatch):
    from napari.plugins._npe2 import get_readers
    from napari.settings import get_settings

    save(tmp_path / "v_seg.nii.gz", np.ones((3, 4, 5), np.uint8))
    # napari's builtins also list .nii.gz (imageio's extensions) but cannot read it
    assert PLUGIN in get_readers(str(tmp_path / "v_seg.nii.gz"))
    monkeypatch.setattr(get_settings().plugins, "extension2reader",
                        {"*.nii.gz": PLUGIN, "*.nii": PLUGIN})
    (layer,) = make_napari_viewer().open(tmp_path / "v_seg.nii.gz", plugin=None)
    assert type(layer).__name__ == "Labels"


def test_mesh_of_a_nifti_labels_layer_lies_on_the_voxels_and_is_written_in_world(
        make_napari_viewer, qtbot, tmp_path):
    labels = np.ones((6, 7, 5), np.uint8)
    labels[1:5, 2:6, 1:4] = 2
    affine = save(tmp_path / "l_seg.nii.gz", labels)
    viewer = make_napari_viewer()
    (layer,) = viewer.open(tmp_path / "l_seg.nii.gz", plugin=PLUGIN)
    widget = MeshWidget(viewer)
    widget.select_labels(layer)
    widget.set_excluded([])
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    surface, mesh = widget.surface_layer, widget.mesh
    assert mesh.world is not None
    # drawn vertices are mesh points in the image frame: corner index times the voxel sizes
    drawn = surface.data[0][:: max(1, len(surface.data[0]) // 60)]
    for vertex in drawn:
        corner = vertex / np.asarray(mesh.spacing)
        np.testing.assert_allclose(surface.data_to_world(vertex),
                                   napari_world(affine, corner - 0.5), atol=1e-9)
        # and the labels layer's voxel centred half a voxel inside agrees
        np.testing.assert_allclose(layer.data_to_world(corner - 0.5),
                                   surface.data_to_world(vertex), atol=1e-9)
    # the mesh the layer keeps (what File > Save writes) is in the NIfTI world
    from napari_swa_imesh._napari._writer import write_mesh_layer

    written = write_mesh_layer(str(tmp_path / "m.vtu"), surface.data,
                               {"name": surface.name, "metadata": surface.metadata})
    corner = mesh.points / np.asarray(mesh.spacing)
    np.testing.assert_allclose(meshio.read(written[0]).points,
                               apply_affine(affine, corner - 0.5), atol=1e-9)


@pytest.mark.parametrize("tiles", [False, True])
def test_classified_labels_of_a_nifti_image_lie_on_it(make_napari_viewer, qtbot, tmp_path,
                                                     tiles):
    from napari_swa_imesh._napari._classify_widget import METHOD_REFERENCE, OUTPUT_TILES
    from napari_swa_imesh._napari._sample_data import make_texture_mosaic
    from napari_swa_imesh._napari._workflow import WorkflowWidget

    (image, _, _), (truth, truth_kwargs, _) = make_texture_mosaic()
    # in-plane rotation by 30 degrees with a flip, 0.5 x 0.8 pixels, an origin
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    affine = np.eye(4)
    affine[:2, :2] = np.array([[c, s], [s, -c]]) @ np.diag([0.5, 0.8])
    affine[:3, 3] = [12.0, -7.0, 3.0]
    affine = save(tmp_path / "mosaic.nii.gz", image.astype(np.float32), affine)
    viewer = make_napari_viewer()
    (layer,) = viewer.open(tmp_path / "mosaic.nii.gz", plugin=PLUGIN)
    truth_layer = viewer.add_labels(truth, **{**truth_kwargs, "scale": layer.scale,
                                               "affine": layer.affine.affine_matrix})
    flow = WorkflowWidget(viewer)
    flow.classify.method_combo.value = METHOD_REFERENCE
    flow.samples.truth_combo.value = truth_layer
    flow.samples.per_material_spin.value = 16
    flow.samples.scale_spin.value = 4
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.classify.scale_combo.value = 4
    if tiles:
        flow.classify.output_combo.value = OUTPUT_TILES
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    labels = viewer.layers["mosaic SWA labels"]
    step = 16 if tiles else 1
    for index in ([0, 0], [3, 7], [10, 2]):
        # label t covers pixels t*step .. t*step + step - 1: its centre is their middle
        centre = np.multiply(index, step) + (step - 1) / 2
        np.testing.assert_allclose(labels.data_to_world(index), layer.data_to_world(centre),
                                   atol=1e-9)
    flow.mesh.select_labels(labels)
    flow.mesh.set_excluded([])
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh, timeout=120_000)
    mesh = flow.mesh.mesh
    corner = mesh.points / np.asarray(mesh.spacing) * step   # pixel-corner index
    written = tmp_path / "m.vtu"
    from napari_swa_imesh.mesh import write_mesh

    write_mesh(mesh, written)
    np.testing.assert_allclose(meshio.read(written).points[:, :2],
                               apply_affine(affine, np.column_stack(
                                   [corner - 0.5, np.zeros(len(corner))]))[:, :2], atol=1e-9)


def test_field_of_a_nifti_mesh_lies_on_the_mesh(make_napari_viewer, qtbot, tmp_path):
    from napari_swa_imesh._napari._simulate_widget import SimulateWidget

    labels = np.ones((5, 6, 4), np.uint8)
    labels[:, 3:] = 2
    save(tmp_path / "l_seg.nii.gz", labels)
    viewer = make_napari_viewer()
    (layer,) = viewer.open(tmp_path / "l_seg.nii.gz", plugin=PLUGIN)
    mesher = MeshWidget(viewer)
    mesher.select_labels(layer)
    mesher.set_excluded([])
    mesher.run_mesh()
    wait_idle(qtbot, mesher, timeout=120_000)
    widget = SimulateWidget(viewer)
    widget.select_mesh(mesher.surface_layer)
    widget.run()
    wait_idle(qtbot, widget, timeout=120_000)
    field = widget.field_layer
    point = mesher.mesh.points[7]
    np.testing.assert_allclose(field.data_to_world(point),
                               mesher.surface_layer.data_to_world(point), atol=1e-9)
    np.testing.assert_allclose(field.affine.affine_matrix, layer.affine.affine_matrix)
