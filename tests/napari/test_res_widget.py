"""RES widget: the Figure 2.14 layout in the dock, and choosing the scale by a click."""

import numpy as np
from swa_napari_helpers import wait_idle
from matplotlib.backend_bases import MouseEvent

from napari_swa_imesh._napari._layers import SCALE_KEY
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.segmentation import res_statistics


def test_res_plot_and_scale_chosen_by_click(mosaic_viewer, qtbot):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.samples.truth_combo.select(truth)
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
    assert flow.res.scale_spin.value() == 2
    assert flow.classify.scale_spin.value() == 2
    assert flow.samples.scale_spin.value() == 2
    assert flow.samples.samples_layer().metadata[SCALE_KEY] == 2
    # the plot is redrawn with the chosen scale as a solid vertical line in every panel
    for ax in flow.res.figure.axes:
        assert any(line.get_linestyle() == "-" and np.allclose(line.get_xdata(), 2)
                   for line in ax.get_lines())


def test_plots_follow_the_napari_theme(mosaic_viewer, qtbot):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.samples.truth_combo.select(truth)
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.res.compute()
    wait_idle(qtbot, flow.res)
    flow.mesh.select_labels(truth)
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh)
    backgrounds = {}
    for theme in ("dark", "light"):
        viewer.theme = theme
        backgrounds[theme] = (flow.res.figure.get_facecolor(), flow.mesh.figure.get_facecolor())
    dark, light = backgrounds["dark"], backgrounds["light"]
    for d, l in zip(dark, light):
        assert sum(d[:3]) < 1.0 < sum(l[:3])      # dark background, then a light one
