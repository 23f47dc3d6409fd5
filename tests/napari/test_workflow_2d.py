"""End to end on the 2-D texture mosaic: samples -> RES -> classify -> mesh -> export."""

import numpy as np
from conftest import wait_idle

from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.mesh._export import read_mesh
from napari_swa_imesh.segmentation import dice_scores


def test_mosaic_workflow(mosaic_viewer, qtbot, tmp_path, notifications):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    viewer.window.add_dock_widget(flow)
    samples = flow.samples
    samples.image_combo.select(image)
    samples.truth_combo.select(truth)
    samples.per_material_spin.setValue(16)
    samples.samples_from_truth()
    wait_idle(qtbot, samples)
    layer = samples.samples_layer()
    print(layer.features)
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    print(flow.res.stats.suggested_scale, flow.classify.scale_spin.value())
    flow.classify.truth_combo.select(truth)
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    print(flow.classify.scores.text())
    labels = viewer.layers[f"{image.name} SWA labels"]
    print(dice_scores(labels.data, truth.data))
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh)
    print(flow.mesh.summary.text())
    surface = flow.mesh.surface_layer
    print(surface.data[0].shape, surface.data[1].shape)
    flow.mesh.color_combo.setCurrentText("material")
    flow.mesh.export_mesh(tmp_path / "m.vtu")
    wait_idle(qtbot, flow.mesh)
    print(read_mesh(tmp_path / "m.vtu"))
    print(notifications.messages())
