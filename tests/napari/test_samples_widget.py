"""Samples widget: drawing with a material, flags, depth in 3-D, JSON round trip."""

import json

import numpy as np
import pytest
from swa_napari_helpers import draw_boxes, rect, wait_idle

from napari_swa_imesh._napari._boxes import box_to_rectangle, rectangles_to_boxes
from napari_swa_imesh._napari._samples_widget import SamplesWidget
from napari_swa_imesh.segmentation import SampleBox, load_samples


def test_rectangles_get_the_current_material_and_its_colour(mosaic_viewer):
    viewer, image, _ = mosaic_viewer
    widget = SamplesWidget(viewer)
    layer = widget.new_samples_layer()
    assert layer.mode == "add_rectangle"
    assert tuple(layer.scale) == tuple(image.scale)
    widget.set_materials([])
    brick = widget.add_material("brick")
    grass = widget.add_material("grass")
    widget.select_material(brick.label)
    layer.add_rectangles([rect(0, 0, 64, 64)])
    widget.select_material(grass.label)
    layer.add_rectangles([rect(100, 100, 164, 164)])
    assert layer.features["name"].tolist() == ["brick", "grass"]
    assert widget.box_table.rowCount() == 2
    assert layer.edge_color[0].tolist() != layer.edge_color[1].tolist()
    samples = widget.current_samples()
    assert [(b.label, b.start, b.stop) for b in samples.boxes] == \
        [(1, (0, 0), (64, 64)), (2, (100, 100), (164, 164))]
    # re-assigning a box changes its material and colour
    layer.selected_data = {1}
    widget.select_material(brick.label)
    widget.assign_selected()
    assert layer.features["label"].tolist() == [1, 1]
    np.testing.assert_allclose(layer.edge_color[1], layer.edge_color[0])


def test_flags_outside_too_small_constant_and_not_a_box(mosaic_viewer):
    viewer, image, _ = mosaic_viewer
    image.data[200:220, 10:30] = 0.5          # a flat patch, as padding would be
    widget = SamplesWidget(viewer)
    layer = widget.new_samples_layer()
    widget.scale_spin.value = 4  # tiles of 16 px
    layer.add_rectangles([rect(0, 0, 64, 64), rect(240, 240, 270, 270), rect(10, 100, 20, 200),
                          rect(200, 10, 220, 30)])
    layer.add_ellipses([rect(100, 100, 120, 120)])
    report = widget.report
    assert report.flags[0] == []
    assert report.flags[1] == ["outside"]
    assert report.flags[2] == ["too small at scale 4"]
    assert "constant" in report.flags[3]
    assert report.flags[4] == ["not a box"]
    assert report.blocking == [1, 4]
    # flags are shown on the canvas (shape text) and in the table, never dropped
    assert "outside" in layer.text.values[1]
    assert widget.box_table.item(2, 3).text() == "too small at scale 4"
    with pytest.raises(ValueError, match="outside the image.*move it inside"):
        widget.current_samples()
    # a larger scale flags more boxes: the flags follow the chosen scale
    widget.set_scale(7)
    assert "too small at scale 7" in widget.report.flags[0]


def test_json_round_trip_through_the_widget(mosaic_viewer, tmp_path, notifications):
    viewer, image, _ = mosaic_viewer
    data = {"materials": [{"label": 1, "name": "brick", "color": "#d62728"},
                          {"label": 2, "name": "grass", "color": "#2ca02c"}],
            "boxes": [{"label": 1, "start": [0, 0], "stop": [64, 128]},
                      {"label": 2, "start": [96, 96], "stop": [160, 160]},
                      {"label": 1, "start": [200, 8], "stop": [240, 40]}]}
    src = tmp_path / "in.json"
    src.write_text(json.dumps(data))
    widget = SamplesWidget(viewer)
    widget.import_samples(src)
    layer = widget.samples_layer()
    assert len(layer.data) == 3
    assert [m.name for m in widget.materials()] == ["brick", "grass"]
    from napari.utils.colormaps.standardize_color import transform_color
    np.testing.assert_allclose(layer.edge_color[1], transform_color("#2ca02c")[0])
    widget.export_samples(tmp_path / "out.json")
    assert load_samples(tmp_path / "out.json").to_dict() == load_samples(src).to_dict()
    assert not notifications.errors
    # a file whose boxes do not fit the image is refused with what to do
    data["boxes"][0]["stop"] = [64, 999]
    src.write_text(json.dumps(data))
    widget.import_samples(src)
    assert any("outside the image" in m and "move or shrink" in m for m in notifications.errors)


def test_3d_rectangle_with_depth_is_a_centred_box(phantom_viewer):
    viewer, image, _ = phantom_viewer
    widget = SamplesWidget(viewer)
    layer = widget.new_samples_layer()
    widget.depth_spin.value = 6
    widget._on_current_material()
    corners = np.array([[20, 9.5, 9.5], [20, 9.5, 29.5], [20, 29.5, 29.5], [20, 29.5, 9.5]])
    layer.add_rectangles([corners])
    (box,) = widget.current_samples().boxes
    assert box.start == (17, 10, 10) and box.stop == (23, 30, 30)
    overlay = viewer.layers[f"{layer.name} extent"]
    assert sorted({float(r[0, 0]) for r in overlay.data}) == [17, 18, 19, 21, 22]
    # changing the depth of the selected box updates the box and its overlay
    layer.selected_data = {0}
    widget.depth_spin.value = 2
    assert widget.current_samples().boxes[0].start[0] == 19
    assert len(overlay.data) == 1


@pytest.mark.parametrize("box", [SampleBox(1, (3, 5), (11, 9)),
                                 SampleBox(2, (4, 0, 2), (9, 16, 3)),
                                 SampleBox(3, (0, 0, 0), (1, 1, 1))])
def test_box_rectangle_round_trip(box):
    d = len(box.start)
    for axis in range(d if d == 3 else 1):
        corners, depth = box_to_rectangle(box, thickness_axis=axis)
        back = rectangles_to_boxes([corners], [box.label], [depth], (32,) * d)
        assert back.boxes[0] == box
        assert back.thickness_axis[0] == (axis if d == 3 else None)


def test_samples_from_truth_match_the_library(mosaic_viewer, qtbot):
    from napari_swa_imesh.segmentation import samples_from_truth

    viewer, image, truth = mosaic_viewer
    widget = SamplesWidget(viewer)
    widget.truth_combo.value = truth
    widget.scale_spin.value = 3
    widget.per_material_spin.value = 5
    widget.samples_from_truth()
    wait_idle(qtbot, widget)
    expected = samples_from_truth(truth.data, scale=3, per_material=5)
    assert widget.current_samples().boxes == expected.boxes
    assert [m.name for m in widget.materials()] == ["brick", "grass"]


def test_a_shapes_layer_drawn_before_the_widget_is_adopted(mosaic_viewer):
    viewer, image, _ = mosaic_viewer
    shapes = viewer.add_shapes([rect(0, 0, 32, 32), rect(64, 64, 128, 96)],
                               shape_type="rectangle", name="my boxes")
    widget = SamplesWidget(viewer)
    widget.samples_combo.value = shapes
    widget._on_samples_layer_selected()
    assert shapes.features["label"].tolist() == [1, 1]
    boxes = widget.current_samples().boxes
    assert [(b.start, b.stop) for b in boxes] == [((0, 0), (32, 32)), ((64, 64), (128, 96))]


def test_a_rectangle_drawn_with_the_mouse_lies_on_the_current_slice(phantom_viewer):
    """Drive napari's own rectangle tool (mouse press, drag, release) on slice 20 of the
    2:1:1 phantom: the box is centred on that slice, in voxel indices."""
    from napari.utils._test_utils import read_only_mouse_event
    from napari.utils.interactions import (
        mouse_move_callbacks,
        mouse_press_callbacks,
        mouse_release_callbacks,
    )

    viewer, image, _ = phantom_viewer
    widget = SamplesWidget(viewer)
    widget.depth_spin.value = 4
    layer = widget.new_samples_layer()
    viewer.dims.set_point(0, 20 * image.scale[0])        # world coordinate of slice 20
    start, end = (40.0, 9.5, 9.5), (40.0, 29.5, 25.5)     # world: pixel edges in-plane
    for kind, position, callbacks in (("mouse_press", start, mouse_press_callbacks),
                                      ("mouse_move", end, mouse_move_callbacks),
                                      ("mouse_release", end, mouse_release_callbacks)):
        event = read_only_mouse_event(type=kind, position=position, dims_displayed=[1, 2],
                                      is_dragging=kind == "mouse_move")
        callbacks(layer, event)
    assert len(layer.data) == 1
    (box,) = widget.current_samples().boxes
    assert box.start == (18, 10, 10) and box.stop == (22, 30, 26)
    assert layer.features["depth"].tolist() == [4]
    assert widget.box_table.rowCount() == 1


def _brick_and_thin_grass(viewer):
    """Brick boxes of 64 px; grass boxes of 16 px (a 16-px tile fits, a 17-px window
    of scale 4 does not) and 10 px (not even a tile)."""
    from napari_swa_imesh._napari._workflow import WorkflowWidget

    flow = WorkflowWidget(viewer)
    layer = draw_boxes(flow.samples, {
        "brick": [rect(0, 0, 64, 64), rect(0, 80, 64, 144)],
        "grass": [rect(100, 100, 116, 156), rect(200, 200, 210, 210)]})
    return flow, layer


def test_material_too_small_for_the_recommended_windows_is_flagged(mosaic_viewer):
    viewer, image, _ = mosaic_viewer
    flow, layer = _brick_and_thin_grass(viewer)
    widget = flow.samples
    widget.set_scale(3)
    assert widget.report.flags == [[], [], [], []]   # 9-px windows fit in the 16-px box
    # the classify tab's scale is the scale in use: the samples tab checks at it
    flow.classify.scale_combo.value = 4
    assert widget.scale_spin.value == 4
    flags = widget.report.flags
    assert flags[0] == flags[1] == []
    assert flags[2] == ["too small for scale 4 windows (needs 17 px)"]
    assert flags[3] == ["too small at scale 4"]      # the existing flag, not repeated
    assert widget.box_table.item(2, 3).text() == "too small for scale 4 windows (needs 17 px)"
    assert "scale 4 windows" in layer.text.values[2]
    # the summary gives the library's sentence: which box to enlarge, to what
    _, sentence = widget.current_samples().window_limit(4)
    assert sentence in widget.summary.value
    assert "enlarge it to at least 17 px" in sentence
    # the flags are warnings: the samples can still be used
    assert widget.report.blocking == []
    # a scale every material can hold clears the flag
    widget.set_scale(3)
    assert widget.report.flags[2] == []
