"""RES widget: the Figure 2.14 layout in the dock, choosing the scale by a click, and the
chosen scale going stale when the samples change."""

import numpy as np
import pytest
from matplotlib.backend_bases import MouseEvent
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari import _samples_layer as sl
from napari_swa_imesh._napari._classify_widget import METHOD_REFERENCE
from napari_swa_imesh._napari._samples_layer import chosen_scale
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.segmentation import res_statistics


def test_res_plot_and_scale_chosen_by_click(mosaic_viewer, qtbot):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.samples.truth_combo.value = truth
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    stats = flow.res.stats
    # the numbers plotted are the library's for the same samples
    expected = res_statistics(image.data, flow.samples.current_samples())
    np.testing.assert_allclose(stats.mean, expected.mean, equal_nan=True)
    axes = flow.res.figure.axes
    assert len(axes) == 4 * len(stats.materials)
    assert [ax.get_ylabel() for ax in axes[::len(stats.materials)]] == \
        ["mean", "variance", "skewness", "kurtosis"]

    # click the mean panel of the first material above scale 2
    ax = axes[0]
    flow.res.canvas.draw()
    x, y = ax.transData.transform((2.2, float(np.nanmean(stats.mean[0, :, 0]))))
    event = MouseEvent("button_press_event", flow.res.canvas, x, y, button=1)
    flow.res.canvas.callbacks.process("button_press_event", event)
    assert flow.res.scale_spin.value == 2
    assert flow.classify.scale_combo.value == 2
    assert flow.samples.scale_spin.value == 2
    assert chosen_scale(flow.samples.samples_layer(), image) == 2
    # the plot is redrawn with the chosen scale as a solid vertical line in every panel
    for ax in flow.res.figure.axes:
        assert any(line.get_linestyle() == "-" and np.allclose(line.get_xdata(), 2)
                   for line in ax.get_lines())


def test_plots_follow_the_napari_theme(mosaic_viewer, qtbot):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.samples.truth_combo.value = truth
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    flow.mesh.select_labels(truth)
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh)
    from matplotlib.colors import to_hex, to_rgb
    from napari.utils.theme import get_theme

    text = {}
    for theme in ("dark", "light"):
        viewer.theme = theme
        text[theme] = (flow.res.figure.axes[0].yaxis.label.get_color(),
                       flow.mesh.figure.axes[0].xaxis.label.get_color())
        # transparent figures: the dock's napari background shows through
        assert flow.res.figure.get_facecolor()[3] == 0 == flow.mesh.figure.get_facecolor()[3]
        assert to_hex(text[theme][1]) == get_theme(theme).text.as_hex()
    for dark, light in zip(text["dark"], text["light"]):
        assert sum(to_rgb(dark)) > 1.5 > sum(to_rgb(light))      # light text, then dark text


def _change_samples(kind, viewer, flow, image):
    """Change the samples (or their image) the way a user would, through napari."""
    layer = flow.samples.samples_layer()
    if kind == "moved":
        data = list(layer.data)
        data[0] = data[0] + np.array([3.0, 5.0])
        layer.data = data
    elif kind == "removed":
        layer.selected_data = set(range(0, len(layer.data), 2))
        layer.remove_selected()
    elif kind == "relabelled":
        layer.selected_data = {0}
        flow.samples.select_material(2)
        flow.samples.assign_selected()
    elif kind == "material renamed":
        flow.samples.material_table.item(0, 1).setText("masonry")
    elif kind == "image edited":
        data = image.data.copy()
        data[:64, :64] = data[:64, :64][::-1]
        image.data = data
    elif kind == "other image":
        other = viewer.add_image(image.data[::-1].copy(), name="flipped",
                                 scale=image.scale, translate=image.translate)
        flow.res.select_layers(image=other)
        flow.classify.select_layers(image=other)
    else:
        raise ValueError(kind)


@pytest.mark.parametrize("kind", ["moved", "removed", "relabelled", "material renamed",
                                  "image edited", "other image"])
def test_res_goes_stale_when_the_samples_change(mosaic_viewer, qtbot, kind):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.samples.truth_combo.value = truth
    flow.samples.per_material_spin.value = 16
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    flow.res.choose_scale(2)
    layer = flow.samples.samples_layer()
    assert chosen_scale(layer, image) == 2 and not flow.res.stale
    assert flow.classify.resolve_scale()[0] == 2

    _change_samples(kind, viewer, flow, image)

    current_image = flow.res.image_combo.value
    # the stored choice carries what it was chosen on, so every consumer sees it is stale
    assert chosen_scale(layer, current_image) is None
    assert sl.scale_choice(layer, current_image).fresh is False
    # the RES tab says so, drops the chosen line and refuses a choice on old numbers
    assert flow.res.stale
    assert "OUT OF DATE" in flow.res.reason.value
    assert not flow.res.scale_spin.enabled
    for ax in flow.res.figure.axes:
        assert not any(line.get_linestyle() == "-" and np.allclose(line.get_xdata(), 2)
                       for line in ax.get_lines())
    flow.res.choose_scale(3)
    assert chosen_scale(layer, current_image) is None
    # the classify tab drops the scale and says where the next one comes from
    assert flow.classify.scale_combo.value is None
    note = flow.classify.scale_note.value
    assert "suggested RES of the current sample boxes" in note and "scale 2" in note
    assert "not used" in note

    # computing again makes the statistics and the choice fresh
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    assert not flow.res.stale and flow.res.scale_spin.enabled
    assert "OUT OF DATE" not in flow.res.reason.value
    suggested = flow.res.stats.suggested_scale
    assert chosen_scale(layer, current_image) == suggested
    assert flow.classify.resolve_scale() == (
        suggested, f"scale {suggested}, chosen on the RES tab for these sample boxes")


def test_classify_after_a_box_change_uses_the_current_suggested_res(mosaic_viewer, qtbot,
                                                                    notifications):
    """The reported bug: a scale chosen on other boxes was reused silently (Dice .885
    instead of the command line's .956). Now the run uses the suggested RES of the boxes
    it trains on, as the command line does, warns, and says so in the panel."""
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.classify.method_combo.value = METHOD_REFERENCE  # one scale: easy to read
    flow.samples.truth_combo.value = truth
    flow.samples.per_material_spin.value = 16
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    flow.res.choose_scale(2)
    assert flow.classify.scale_combo.value == 2

    layer = flow.samples.samples_layer()
    layer.selected_data = set(range(0, len(layer.data), 2))
    layer.remove_selected()
    current = flow.samples.current_samples()
    expected = res_statistics(image.data, current, method="reference").suggested_scale
    assert expected != 2       # otherwise the test could not tell the two apart

    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    assert flow.classify.result.scale == expected
    note = flow.classify.scale_note.value
    assert note.startswith(f"Last run: tiles of scale {expected}: the suggested RES of "
                           f"these boxes, {expected}.")
    assert any("classifying at the suggested RES" in w and "scale 2" in w
               for w in notifications.messages("warning"))
    assert not notifications.errors


@pytest.mark.parametrize("stale", [False, True])
def test_figure_title_clears_the_column_titles(mosaic_viewer, stale):
    from napari_swa_imesh._napari._res_widget import ResWidget
    from napari_swa_imesh.segmentation import samples_from_truth

    viewer, image, truth = mosaic_viewer
    widget = ResWidget(viewer)
    widget.figure.set_size_inches(6.0, 12.0)       # drawn first in a tall dock
    widget.show_stats(res_statistics(image.data, samples_from_truth(truth.data, scale=3)))
    if stale:
        widget.stale = True
        widget._draw()
    figure = widget.figure
    (title,) = [t for t in figure.texts if t.get_text() == figure.get_suptitle()]
    assert ("OUT OF DATE" in title.get_text()) == stale
    # then the dock is made shorter: the layout must follow
    for size in ((6.0, 12.0), (4.0, 4.0)):
        figure.set_size_inches(*size)
        widget.canvas.draw()
        renderer = widget.canvas.get_renderer()
        top = title.get_window_extent(renderer)
        columns = [ax.title for ax in figure.axes if ax.get_title()]
        assert len(columns) == 2
        for column in columns:
            box = column.get_window_extent(renderer)
            assert box.y1 <= top.y0, (size, top, box)   # column titles below the title
