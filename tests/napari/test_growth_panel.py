"""The Simulate tab's reaction-diffusion section: a run from the tab's mesh and labels,
D from the material table, the time slider swapping the field on the mesh."""

import numpy as np
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._growth_panel import GROWTH_KEY
from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._simulate_widget import SimulateWidget


def test_fisher_kpp_from_the_tab_with_a_time_slider(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = np.full((10, 14), 2, dtype=np.uint8)
    labels[5:] = 3
    labels[:, :2] = 1                                  # CSF: D = 0 below
    layer = viewer.add_labels(labels, name="brain")
    mesher = MeshWidget(viewer)
    mesher.select_labels(layer)
    mesher.set_excluded([])
    mesher.run_mesh()
    wait_idle(qtbot, mesher, timeout=120_000)
    widget = SimulateWidget(viewer)
    widget.select_mesh(mesher.surface_layer)
    widget.labels_combo.value = layer
    panel = widget.growth
    for label, value in ((1, "0"), (2, "4"), (3, "1")):
        widget.table.set_value(label, value)
    panel.seed.value = "7,5:2"
    panel.duration.value = 2.0
    panel.saves.value = 4
    panel.run()
    wait_idle(qtbot, widget, timeout=120_000)
    result = panel.result
    assert result is not None and result.times.tolist() == [0, 0.5, 1, 1.5, 2]
    assert set(np.unique(result.mesh.material)) == {2, 3}          # CSF not meshed
    assert result.diffusivity == {2: 4.0, 3: 1.0}
    assert panel.layer.metadata[GROWTH_KEY] == "fisher-kpp"
    assert np.allclose(panel.layer.data[2], result.values[-1])
    panel.time_slider.value = 1
    assert np.allclose(panel.layer.data[2], result.values[1])
    assert "t = 0.5" in panel.time_note.value
    assert result.amount[-1] > result.amount[0]
    assert 0 <= result.values.min() and result.values.max() <= 1
    panel.seed.value = "700,5:2"                       # outside the image: the worker refuses
    panel.run()
    wait_idle(qtbot, widget, timeout=120_000)
    assert panel.summary.value == "" and not panel.time_slider.enabled


def test_a_tensor_diffusivity_is_refused_before_any_work(make_napari_viewer, qtbot,
                                                          monkeypatch):
    from napari_swa_imesh._napari import _growth_panel

    errors = []
    monkeypatch.setattr(_growth_panel, "notify_error", errors.append)
    viewer = make_napari_viewer()
    layer = viewer.add_labels(np.ones((6, 6), dtype=np.uint8), name="one")
    mesher = MeshWidget(viewer)
    mesher.select_labels(layer)
    mesher.set_excluded([])
    mesher.run_mesh()
    wait_idle(qtbot, mesher, timeout=120_000)
    widget = SimulateWidget(viewer)
    widget.select_mesh(mesher.surface_layer)
    widget.table.set_value(1, "1, 2")
    assert widget.growth.run() is None
    assert errors and "one number" in errors[0]
    assert widget.growth.result is None and not widget.tasks.busy
