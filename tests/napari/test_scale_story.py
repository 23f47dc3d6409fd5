"""One story about the scale (issue 23, sec. 3): the RES tab suggests a scale the classifier
trains at, names the box that limits it once, and the classify panel says plainly which
scales ran and why, each warning once."""

from swa_napari_helpers import draw_boxes, rect, wait_idle

from napari_swa_imesh._napari._classify_widget import METHOD_RECOMMENDED
from napari_swa_imesh._napari._workflow import WorkflowWidget


def _narrow_grass(viewer):
    """Brick boxes of 64 px and one grass box 4 px wide: no 5-px window fits in it."""
    flow = WorkflowWidget(viewer)
    draw_boxes(flow.samples, {"brick": [rect(0, 0, 64, 64), rect(0, 80, 64, 144)],
                              "grass": [rect(150, 150, 230, 154)]})
    return flow


def test_suggested_scale_is_the_one_that_runs(mosaic_viewer, qtbot, notifications):
    viewer, image, truth = mosaic_viewer
    flow = _narrow_grass(viewer)
    assert flow.classify.method_combo.value == METHOD_RECOMMENDED
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    stats = flow.res.stats
    trains = min(flow.samples.current_samples().window_scales().values())
    assert stats.suggested_scale == trains == 1
    # the reason names the limiting box once, with what to do
    assert flow.res.reason.value.count("'grass' (box #2") == 1
    assert flow.classify.scale_combo.value == stats.suggested_scale
    assert "Warning" not in flow.classify.scale_note.value

    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    result = flow.classify.result
    assert result.model.scores["top_scale"] == stats.suggested_scale
    note = flow.classify.scale_note.value
    assert note.startswith(f"Last run: labels from scales {', '.join(map(str, result.scales))}"
                           f"; coarse scale {result.scale} picked by cross-validation among "
                           f"0..{stats.suggested_scale}. Largest scale asked: scale "
                           f"{stats.suggested_scale}, chosen on the RES tab")
    assert "Warning" not in note
    assert not [w for w in notifications.messages("warning") if "windows of" in w]


def test_a_scale_above_the_limit_is_lowered_and_said_once(mosaic_viewer, qtbot,
                                                          notifications):
    viewer, image, truth = mosaic_viewer
    flow = _narrow_grass(viewer)
    flow.classify.scale_combo.value = 3
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    note = flow.classify.scale_note.value
    assert flow.classify.result.model.scores["top_scale"] == 1
    assert "among 0..1. Largest scale asked: scale 3, set in this panel." in note
    assert note.count("scale 3 needs windows of 9 px") == 1
    assert "using scales up to 1" in note
    assert any("windows of 9 px" in w for w in notifications.messages("warning"))
