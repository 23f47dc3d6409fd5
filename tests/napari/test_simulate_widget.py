"""Simulate widget: k_eff of a mesh layer with the table's conductivities, the field shown."""

import meshio
import numpy as np
import pytest
from swa_napari_helpers import Notifications, wait_idle

from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._simulate_widget import FIELD_KEY, SimulateWidget
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.simulate import simulate


def _meshed(viewer, qtbot, labels, name="layers"):
    layer = viewer.add_labels(labels, name=name)
    mesher = MeshWidget(viewer)
    mesher.select_labels(layer)
    mesher.set_excluded([])
    mesher.run_mesh()
    wait_idle(qtbot, mesher, timeout=120_000)
    return mesher.surface_layer


def test_k_eff_of_layers_in_series_and_the_field_on_the_surface(make_napari_viewer, qtbot,
                                                                tmp_path):
    viewer = make_napari_viewer()
    labels = np.ones((12, 16), dtype=np.uint8)
    labels[:, 8:] = 2
    surface = _meshed(viewer, qtbot, labels)
    widget = SimulateWidget(viewer)
    widget.select_mesh(surface)
    assert [r.label for r in widget.table.records] == [1, 2]
    widget.table.set_value(2, "3")
    widget.order_combo.value = "P2 (quadratic, more accurate)"
    widget.run()
    wait_idle(qtbot, widget, timeout=120_000)
    result = widget.result
    assert result.k_eff["x"] == pytest.approx(1.5, rel=1e-9)      # harmonic mean of 1, 3
    assert result.k_eff["y"] == pytest.approx(2.0, rel=1e-9)      # arithmetic mean
    assert "k_eff x = 1.5" in widget.summary.value
    # the certified interval: exact for layers, shown in the summary and the figure
    assert result.interval["x"] == pytest.approx((1.5, 1.5), rel=1e-9)
    assert "certified 1.5 .. 1.5" in widget.summary.value
    assert "certified x: 1.5 <= k_eff <= 1.5" in widget.summary.native.toolTip()
    assert "certified" in [t.get_text() for t in
                           widget.figure.axes[1].get_legend().get_texts()]
    field = widget.field_layer
    assert field.metadata[FIELD_KEY] == "x"
    assert np.allclose(field.data[2], result.potential["x"])
    assert field.data[2].min() == pytest.approx(0) and field.data[2].max() == pytest.approx(1)
    widget.show_combo.value = "y"
    assert np.allclose(field.data[2], result.potential["y"])
    assert len(widget.figure.axes) == 2
    # export goes through the library writer; meshio reads the fields back
    widget.export_field(tmp_path / "field.vtu")
    wait_idle(qtbot, widget)
    written = meshio.read(tmp_path / "field.vtu")
    assert np.allclose(written.point_data["potential_x"], result.potential["x"])


def test_a_bad_conductivity_is_refused_before_any_work(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = np.ones((8, 8), dtype=np.uint8)
    labels[4:] = 2
    widget = SimulateWidget(viewer)
    widget.select_mesh(_meshed(viewer, qtbot, labels))
    notes = Notifications()
    widget.table.set_value(1, "soft")
    assert widget.run() is None
    assert any("is not a number" in m for m in notes.errors)
    widget.table.set_value(1, "-2")
    widget.run()
    wait_idle(qtbot, widget)
    assert widget.result is None
    assert any("must be positive" in m for m in notes.errors)


def test_the_workflow_hands_the_mesh_to_the_simulate_tab(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = np.random.default_rng(0).integers(1, 3, (10, 9, 8)).astype(np.uint8)
    layer = viewer.add_labels(labels)
    flow = WorkflowWidget(viewer)
    flow.mesh.select_labels(layer)
    flow.mesh.set_excluded([])
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh, timeout=120_000)
    assert flow.simulate.mesh_combo.value is flow.mesh.surface_layer
    flow.simulate.table.set_value(2, "10")
    flow.simulate.axis_boxes["y"].value = False
    flow.simulate.run()
    wait_idle(qtbot, flow.simulate, timeout=120_000)
    # the default adapts the mesh with the labels it was made from, as the library does
    expected = simulate(flow.mesh.mesh, {1: 1.0, 2: 10.0}, axes=["x", "z"], labels=labels)
    assert flow.simulate.result.k_eff == pytest.approx(expected.k_eff, rel=1e-9)
    assert flow.simulate.result.choice == expected.choice == "P2, 1 adaptive step"
