"""Error paths reach the user as notifications that say what to do; Cancel stops a run."""

import threading

import pytest
from swa_napari_helpers import draw_boxes, rect, wait_idle

from napari_swa_imesh._napari import _classify_widget, _mesh_widget
from napari_swa_imesh._napari._classify_widget import METHOD_REFERENCE, ClassifyWidget
from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh._napari._res_widget import ResWidget
from napari_swa_imesh._napari._samples_widget import SamplesWidget
from napari_swa_imesh._napari._tasks import error_sentence
from napari_swa_imesh._napari._workflow import WorkflowWidget


def test_no_image_layer(make_napari_viewer, notifications):
    viewer = make_napari_viewer()
    flow = WorkflowWidget(viewer)
    assert flow.samples.new_samples_layer() is None
    assert flow.res.compute() is None
    assert flow.classify.classify() is None
    assert flow.mesh.run_mesh() is None
    errors = notifications.errors
    assert len(errors) == 4
    assert "open an image" in errors[0] and "File > Open Sample" in errors[0]
    assert "open an image" in errors[1]
    assert "open an image" in errors[2]
    assert "classify an image first" in errors[3]
    assert len(viewer.layers) == 0


def _brick_and_tiny_grass(viewer, image):
    samples = SamplesWidget(viewer)
    layer = draw_boxes(samples, {"brick": [rect(0, 0, 128, 128)],
                                 "grass": [rect(100, 100, 108, 108)]})  # 8 px: < 16-px tiles
    return samples, layer


def test_box_too_small_for_the_scale(mosaic_viewer, qtbot, notifications):
    viewer, image, _ = mosaic_viewer
    samples, layer = _brick_and_tiny_grass(viewer, image)
    samples.set_scale(4)
    assert samples.report.flags[1] == ["too small at scale 4"]
    classify = ClassifyWidget(viewer)
    classify.method_combo.value = METHOD_REFERENCE  # tiles need whole-tile boxes
    classify.samples_combo.value = layer
    classify.scale_combo.value = 4
    n_layers = len(viewer.layers)
    classify.classify()
    wait_idle(qtbot, classify)
    warnings = notifications.messages("warning")
    assert any("smaller than one tile at scale 4" in w and "enlarge them" in w for w in warnings)
    (error,) = notifications.errors
    assert "'grass'" in error and "enlarge its box" in error and "use scale 1 or less" in error
    assert classify.tasks.last_error == error
    assert len(viewer.layers) == n_layers        # no labels layer
    # the same boxes work at a scale they can hold
    classify.scale_combo.value = 1
    classify.classify()
    wait_idle(qtbot, classify)
    assert len(viewer.layers) == n_layers + 1
    assert len(notifications.errors) == 1


def test_box_outside_the_image_is_refused_before_running(mosaic_viewer, notifications):
    viewer, image, _ = mosaic_viewer
    samples, layer = _brick_and_tiny_grass(viewer, image)
    layer.add_rectangles([rect(200, 200, 300, 300)])
    res = ResWidget(viewer)
    res.samples_combo.value = layer
    assert res.compute() is None
    (error,) = notifications.errors
    assert "box 3 (grass)" in error and "outside the image" in error
    assert "move it inside the image or delete it" in error


def test_unexpected_errors_still_say_what_to_do():
    assert error_sentence("X", ValueError("draw larger boxes.")) == "X failed: draw larger boxes."
    message = error_sentence("X", KeyError("k"))
    assert "unexpected KeyError" in message and "report this" in message


@pytest.fixture
def gate(monkeypatch):
    """Hold the worker after its first step until the test has pressed Cancel."""
    event = threading.Event()
    real_steps, real_mesh = _classify_widget.segment_steps, _mesh_widget.mesh_labels

    def held_steps(*args, **kwargs):
        gen = real_steps(*args, **kwargs)
        yield next(gen)
        assert event.wait(10)
        return (yield from gen)

    def held_mesh(*args, **kwargs):
        assert event.wait(10)
        return real_mesh(*args, **kwargs)

    monkeypatch.setattr(_classify_widget, "segment_steps", held_steps)
    monkeypatch.setattr(_mesh_widget, "mesh_labels", held_mesh)
    return event


def _cancel_on_first_report(panel, event):
    """Press Cancel when the first step is reported, then let the worker go on."""
    def on_report(*_):
        if panel.cancel_button.isEnabled():
            panel.cancel_button.click()
        event.set()
    panel.reported.connect(on_report)


def test_cancel_classification_mid_run(phantom_viewer, qtbot, gate, notifications):
    viewer, image, truth = phantom_viewer
    flow = WorkflowWidget(viewer)
    flow.samples.truth_combo.value = truth
    flow.samples.scale_spin.value = 2
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    n_layers = len(viewer.layers)
    flow.classify.scale_combo.value = 2
    _cancel_on_first_report(flow.classify.tasks, gate)
    worker = flow.classify.classify()
    aborted = []
    worker.aborted.connect(lambda: aborted.append(True))
    wait_idle(qtbot, flow.classify)
    assert aborted == [True]
    assert len(viewer.layers) == n_layers
    assert flow.classify.result is None
    assert flow.classify.tasks.status.text().endswith("cancelled")
    assert any("cancelled" in m for m in notifications.messages("info"))
    assert not notifications.errors


def test_cancel_meshing_mid_run(phantom_viewer, qtbot, gate, notifications):
    viewer, image, truth = phantom_viewer
    mesh = MeshWidget(viewer)
    mesh.select_labels(truth)
    n_layers = len(viewer.layers)
    _cancel_on_first_report(mesh.tasks, gate)
    mesh.run_mesh()
    wait_idle(qtbot, mesh)
    assert gate.is_set()
    assert len(viewer.layers) == n_layers
    assert mesh.mesh is None and mesh.surface_layer is None
    assert not mesh.export_button.enabled
    assert mesh.tasks.status.text().endswith("cancelled")
    assert not notifications.errors


def test_writer_refuses_a_surface_without_a_mesh(make_napari_viewer, tmp_path):
    from napari_swa_imesh._napari._writer import write_mesh_layer

    with pytest.raises(ValueError, match="holds no IMESH mesh; mesh a Labels layer"):
        write_mesh_layer(str(tmp_path / "x.vtu"), None, {"name": "s", "metadata": {}})
