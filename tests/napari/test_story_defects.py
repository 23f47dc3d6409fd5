"""Defects a user met in the GUI (issue 23, sec. 4), each reproduced as the user met it."""

from swa_napari_helpers import add_layer_data, wait_idle

from napari_swa_imesh._napari._classify_widget import METHOD_REFERENCE
from napari_swa_imesh._napari._sample_data import make_texture_mosaic, make_tissue_phantom
from napari_swa_imesh._napari._workflow import WorkflowWidget


def _run_through(flow, qtbot, truth, *, per_material=4):
    flow.samples.truth_combo.value = truth
    flow.samples.per_material_spin.value = per_material
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.classify.method_combo.value = METHOD_REFERENCE       # fastest
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh, timeout=120_000)
    flow.simulate.run()
    wait_idle(qtbot, flow.simulate, timeout=120_000)


def test_material_names_do_not_leak_to_the_next_image(make_napari_viewer, qtbot,
                                                      notifications):
    """Mosaic through Simulate, delete the layers, then the phantom through Simulate: the
    signatures and the mesh name the phantom's materials the same way (the user saw
    "the signatures name material 1 'csf' but the mesh names it 'material 1'")."""
    viewer = make_napari_viewer()
    flow = WorkflowWidget(viewer)
    viewer.window.add_dock_widget(flow)
    _, truth = add_layer_data(viewer, make_texture_mosaic())
    _run_through(flow, qtbot, truth)
    assert not notifications.errors, notifications.errors
    viewer.layers.clear()
    _, truth = add_layer_data(viewer, make_tissue_phantom(shape=(16, 32, 32)))
    _run_through(flow, qtbot, truth, per_material=2)
    assert not notifications.errors, notifications.errors
    assert flow.simulate.report.report is not None
