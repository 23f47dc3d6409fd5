"""The Simulate tab's stochastic box: signatures in, k_eff mean +- interval and histogram out."""

import numpy as np
from swa_napari_helpers import Notifications, wait_idle

from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._simulate_widget import SimulateWidget
from napari_swa_imesh.simulate import stochastic_k_eff

ROWS = [{"label": 1, "name": "a", "tiles": 9, "mean_mean": 0.0, "mean_std": 0.5, "scale": 2},
        {"label": 2, "name": "b", "tiles": 9, "mean_mean": 1.0, "mean_std": 0.2, "scale": 2}]


def _tab(viewer, qtbot):
    labels = np.ones((12, 16), dtype=np.uint8)
    labels[:, 8:] = 2
    layer = viewer.add_labels(labels, name="layers")
    mesher = MeshWidget(viewer)
    mesher.select_labels(layer)
    mesher.set_excluded([])
    mesher.run_mesh()
    wait_idle(qtbot, mesher, timeout=120_000)
    widget = SimulateWidget(viewer)
    widget.select_mesh(mesher.surface_layer, layer)
    return widget, labels


def test_the_box_runs_the_library_and_shows_mean_interval_and_histogram(make_napari_viewer,
                                                                        qtbot):
    viewer = make_napari_viewer()
    widget, labels = _tab(viewer, qtbot)
    box = widget.stochastic
    assert not widget.stochastic_box.is_open              # folded: the tab's fold unchanged
    box.set_signatures(ROWS, "test")
    assert "test (2 materials)" in box.source_label.value
    box.samples_spin.value = 4
    box.map_edit.value = "log-linear:0,1"
    box.seed_spin.value = 3
    box.run()
    wait_idle(qtbot, box, timeout=120_000)
    expected = stochastic_k_eff(labels, ROWS, samples=4, correlation=4.0, seed=3,
                                spacing=(1.0, 1.0), material_names={1: "a", 2: "b"})
    assert np.array_equal(box.result.samples["x"], expected.samples["x"])
    assert box.result.correlation == (4.0, 4.0)          # tile size 0: 2^scale of the rows
    s = expected.statistics("x")
    assert f"k_eff x = {s['mean']:.5g}" in box.summary.value
    assert "95 % of samples in" in box.summary.value
    assert len(box.plot.figure.axes) == 1
    assert box.plot.figure.axes[0].get_xlabel() == "k_eff"
    box.map_edit.value = "linear:1"                        # fails in the worker
    box.run()
    wait_idle(qtbot, box)
    assert box.result is None and box.summary.value == ""  # the last run is not shown
    assert not box.plot.figure.axes


def test_the_box_refuses_without_signatures_and_with_a_bad_map(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    widget, _ = _tab(viewer, qtbot)
    box = widget.stochastic
    notes = Notifications()
    assert box.run() is None
    assert any("no signatures" in m for m in notes.errors)
    box.set_signatures(ROWS, "test")
    box.map_edit.value = "linear:1"
    box.run()
    wait_idle(qtbot, box)
    assert box.result is None
    assert any("must be log-linear:a,b" in m for m in notes.errors)


def test_cancel_stops_the_samples(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    widget, _ = _tab(viewer, qtbot)
    box = widget.stochastic
    box.set_signatures(ROWS, "test")
    box.samples_spin.value = 400
    seen = []

    def cancel_once(done, total, message):
        if "samples solved" in message and not seen:
            seen.append(done)
            box.tasks.cancel_button.click()

    box.tasks.reported.connect(cancel_once)
    box.run()
    wait_idle(qtbot, box, timeout=120_000)
    assert seen and box.result is None
    assert box.tasks.status.text().endswith("cancelled")


def test_a_tile_size_in_the_box_overrides_the_signatures(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    widget, _ = _tab(viewer, qtbot)
    box = widget.stochastic
    box.set_signatures(ROWS, "test")
    box.samples_spin.value = 2
    box.tile_spin.value = 3.0
    box.run()
    wait_idle(qtbot, box, timeout=120_000)
    assert box.result.correlation == (3.0, 3.0)


def test_the_unfolded_box_fits_the_laptop_dock(make_napari_viewer):
    from qtpy.QtWidgets import QScrollArea

    widget = SimulateWidget(make_napari_viewer())
    area = widget.findChild(QScrollArea)
    folded = area.widget().minimumSizeHint().width()
    widget.stochastic_box.set_open(True)
    assert widget.stochastic_box.body.isVisibleTo(widget)
    width = area.widget().minimumSizeHint().width()
    print(f"Simulate tab content: {folded} px folded, {width} px with the stochastic box open")
    assert width <= max(folded, 384)      # the dock's width on a 1280x800 screen


def test_the_box_follows_the_labels_classification(make_napari_viewer):
    from napari_swa_imesh._napari._classify_widget import SEGMENTATION_KEY

    viewer = make_napari_viewer()
    widget = SimulateWidget(viewer)
    classified = viewer.add_labels(np.ones((8, 8), dtype=np.uint8), name="classified",
                                   metadata={SEGMENTATION_KEY: {"signatures": ROWS}})
    plain = viewer.add_labels(np.ones((8, 8), dtype=np.uint8), name="plain")
    widget.labels_combo.value = classified
    assert widget.stochastic.signatures == ROWS
    assert "classification of 'classified'" in widget.stochastic.source_label.value
    widget.labels_combo.value = plain
    assert widget.stochastic.signatures is None          # not these labels' signatures
