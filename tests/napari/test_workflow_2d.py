"""End to end on the 2-D texture mosaic: samples -> RES -> classify -> mesh -> export.

Dice thresholds: with 16 samples per material taken from the truth, the statistics settle
at 5 (32-px tiles), the suggested RES is 4 (the scale the classifier trains at in 32-px
boxes) and the run measured Dice 0.949 (brick) and 0.848 (grass, the disc: its
boundary is staircased by 32-px tiles). The thresholds sit a few points below; labelling
every pixel "brick" would give 0.78 / 0.0 and a random labelling about 0.6 / 0.4.
"""

import numpy as np
import pytest
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._classify_widget import SEGMENTATION_KEY
from napari_swa_imesh._napari._layers import MESH_KEY
from napari_swa_imesh._napari._mesh_widget import COLOR_BY_MATERIAL, COLOR_BY_QUALITY
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.mesh.checks._checks import check_mesh
from napari_swa_imesh.mesh.formats._export import read_mesh
from napari_swa_imesh.segmentation import dice_scores

MIN_DICE = {1: 0.92, 2: 0.80}


def test_mosaic_workflow(mosaic_viewer, qtbot, tmp_path, notifications):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    viewer.window.add_dock_widget(flow)

    # samples: from the truth, named after it, coloured by material
    samples = flow.samples
    samples.image_combo.value = image
    samples.truth_combo.value = truth
    samples.per_material_spin.value = 16
    samples.samples_from_truth()
    wait_idle(qtbot, samples)
    layer = samples.samples_layer()
    assert len(layer.data) == 32
    assert set(layer.features["name"]) == {"brick", "grass"}
    colors = {m.label: m.color for m in samples.materials()}
    edge = layer.edge_color[layer.features["label"].to_numpy() == 2]
    from napari.utils.colormaps.standardize_color import transform_color
    np.testing.assert_allclose(edge, np.repeat(transform_color(colors[2]), len(edge), 0))

    # RES: the suggested scale becomes the chosen one and reaches the classifier
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    stats = flow.res.stats
    # the statistics settle at 5 (32-px tiles); the recommended method's 33-px windows do
    # not fit in the 32-px boxes, so the suggestion is 4, the scale it trains at
    assert stats.suggested_scale == 4
    assert flow.res.scale_spin.value == 4
    assert flow.classify.scale_combo.value == 4
    assert len(flow.res.figure.axes) == 4 * 2      # moments x materials
    assert "Suggested RES: 4" in flow.res.reason.value and "Capped at 4" in stats.reason

    # classify with the defaults (F1, GM, chosen RES), Dice against the truth
    assert flow.classify.feature_combo.value == "F1"
    assert flow.classify.classifier_combo.value == "GM"
    flow.classify.truth_combo.value = truth
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    labels = viewer.layers[f"{image.name} SWA labels"]
    assert labels.data.shape == image.data.shape
    dice = dice_scores(labels.data, truth.data)
    assert all(dice[k] > MIN_DICE[k] for k in MIN_DICE), dice
    assert flow.classify.dice == pytest.approx(dice)
    # the classifier runs at the suggested RES as it is: nothing lowers it any more
    assert labels.metadata[SEGMENTATION_KEY]["scale"] == 4
    assert "Warning" not in flow.classify.scale_note.value
    assert "eps_l" in flow.classify.scores.value and "Dice" in flow.classify.scores.value
    assert flow.classify.signature_table.rowCount() == 2

    # mesh: the classification is passed on; checks pass; one vertex triple per triangle
    assert flow.mesh.labels_combo.value is labels
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh)
    mesh = flow.mesh.mesh
    assert flow.mesh.checks["all_passed"]
    assert "checks: all passed" in flow.mesh.summary.value
    surface = flow.mesh.surface_layer
    vertices, triangles, values = surface.data
    assert len(triangles) == mesh.n_cells
    assert len(vertices) == 3 * len(triangles)
    np.testing.assert_allclose(values, np.repeat(mesh.quality, 3))
    assert flow.mesh.figure.axes, "quality histogram drawn"
    # colour toggle: by material every triangle has one colour on its three vertices
    flow.mesh.color_combo.value = COLOR_BY_MATERIAL
    colors = surface.vertex_colors.reshape(-1, 3, 4)
    assert (colors == colors[:, :1]).all()
    assert len(np.unique(colors[:, 0], axis=0)) == 2
    flow.mesh.color_combo.value = COLOR_BY_QUALITY
    assert surface.vertex_colors is None or len(surface.vertex_colors) == 0

    # export through the widget and through napari's Save (the npe2 writer)
    flow.mesh.export_mesh(tmp_path / "mosaic.vtu")
    wait_idle(qtbot, flow.mesh)
    back = read_mesh(tmp_path / "mosaic.vtu")
    assert back.n_cells == mesh.n_cells
    np.testing.assert_array_equal(np.sort(back.material), np.sort(mesh.material))
    viewer.layers.selection = {surface}
    # no plugin named: napari finds the writer from the layer type and the suffix
    written = viewer.layers.save(str(tmp_path / "mosaic.msh"), selected=True)
    assert written == [str(tmp_path / "mosaic.msh")]
    back = read_mesh(tmp_path / "mosaic.msh")
    assert back.n_cells == mesh.n_cells
    assert surface.metadata[MESH_KEY] is mesh
    # the written mesh, read back, still passes every check against the labels
    assert check_mesh(back, labels.data)["all_passed"]
    assert not notifications.errors
