"""The workflow dock on a 1280x800 laptop screen (pytest-xvfb's screen, set in pyproject).

Reported case: napari opened at 1089x630, the workflow dock took 506 px and left the canvas
about 235 px; the Simulate tab was wider than the dock, so its controls hid behind a
horizontal scroll bar; "Samples from truth" and the k_eff result sat below the fold.
Measured before the change with the window at 1280x800: dock 508 px, canvas 426 px (33 %),
Simulate scrolled sideways (content 573 px wide) and its Simulate button and k_eff result
were out of view. Now: dock 384 px, canvas 550 px (43 %) on every tab, no tab scrolls
sideways and every tab shows its action button and its whole result.
"""

import pytest
from qtpy.QtWidgets import QApplication, QScrollArea
from swa_napari_helpers import add_layer_data, wait_idle

SCREEN = (1280, 800)
MAX_DOCK = 400          # px
MIN_CANVAS = 0.40       # of the window's width (napari's layer panel takes about 300 px)


def _laptop_window(viewer):
    window = viewer.window._qt_window
    screen = QApplication.primaryScreen().availableGeometry()
    if screen.width() < SCREEN[0] or screen.height() < SCREEN[1]:
        pytest.skip(f"a {screen.width()}x{screen.height()} screen is smaller than a laptop's")
    # maximised (Xvfb has no window manager to maximise it)
    window.resize(*SCREEN)
    QApplication.processEvents()
    return window


def _in_view(widget, area: QScrollArea) -> bool:
    """Whether the whole of `widget` shows in the scroll area's viewport, unscrolled."""
    widget = getattr(widget, "native", widget)
    viewport = area.viewport()
    top_left = widget.mapTo(viewport, widget.rect().topLeft())
    bottom_right = widget.mapTo(viewport, widget.rect().bottomRight())
    return (widget.isVisibleTo(area) and top_left.x() >= 0 and top_left.y() >= 0
            and bottom_right.x() < viewport.width() and bottom_right.y() < viewport.height())


def test_workflow_fits_a_laptop_screen(make_napari_viewer, qtbot):
    from napari_swa_imesh._napari._sample_data import make_texture_mosaic

    viewer = make_napari_viewer(show=True)
    image, truth = add_layer_data(viewer, make_texture_mosaic())
    window = _laptop_window(viewer)
    dock, flow = viewer.window.add_plugin_dock_widget("napari-swa-imesh", "Segment and mesh")
    flow.samples.truth_combo.value = truth
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    for tab, step in ((flow.res, flow.res.compute), (flow.classify, flow.classify.classify),
                      (flow.mesh, flow.mesh.run_mesh)):
        step()
        wait_idle(qtbot, tab)
    flow.simulate.select_mesh(flow.mesh.surface_layer)
    flow.simulate.run()
    wait_idle(qtbot, flow.simulate)
    assert flow.simulate.result is not None
    canvas = viewer.window._qt_viewer.canvas.native
    action_and_result = {
        "Samples": (flow.samples.truth_button, flow.samples.summary),
        "RES": (flow.res.compute_button, flow.res.reason),
        "Classify": (flow.classify.classify_button, flow.classify.scores),
        "Mesh": (flow.mesh.mesh_button, flow.mesh.summary),
        "Simulate": (flow.simulate.run_button, flow.simulate.summary)}
    for index in range(flow.tabs.count()):
        flow.tabs.setCurrentIndex(index)
        qtbot.wait(50)
        name, area = flow.tabs.tabText(index), flow.tabs.widget(index).findChild(QScrollArea)
        button, result = action_and_result[name]
        print(f"{name}: window {window.width()}x{window.height()}, dock {dock.width()} px, "
              f"canvas {canvas.width()} px ({canvas.width() / window.width():.0%}), content "
              f"{area.widget().minimumSizeHint().width()} px wide in {area.viewport().width()}")
        assert (window.width(), window.height()) == SCREEN
        assert dock.width() <= MAX_DOCK, name
        assert canvas.width() >= MIN_CANVAS * window.width(), name
        assert not area.horizontalScrollBar().isVisible(), name
        assert area.widget().minimumSizeHint().width() <= area.viewport().width(), name
        assert result.value, name                    # a result is shown, not an empty line
        assert _in_view(button, area), f"{name}: action button below the fold"
        assert _in_view(result, area), f"{name}: result below the fold"


def test_sections_fold_away_and_unfold(make_napari_viewer):
    from napari_swa_imesh._napari._dock import Fold
    from napari_swa_imesh._napari._simulate_widget import SimulateWidget

    widget = SimulateWidget(make_napari_viewer())
    folds = widget.findChildren(Fold)
    assert {fold.toggle.text() for fold in folds} == {
        "see inside", "signatures and k_eff report",
        "stochastic k_eff from the signatures",
        "reaction-diffusion (tumour growth, drug)"}
    assert not widget.stochastic_box.is_open            # folded: below the fold stays short
    assert not widget.growth.fold.is_open               # folded: the k_eff run stays in view
    clip = widget.clip_box
    assert not clip.is_open and not clip.body.isVisibleTo(widget)
    clip.toggle.click()
    assert clip.is_open and clip.body.isVisibleTo(widget)
    assert widget.clip.enable_box.native.isVisibleTo(widget)
    clip.toggle.click()
    assert not clip.body.isVisibleTo(widget)


def test_a_long_check_box_text_wraps_and_still_toggles(make_napari_viewer, qtbot):
    from qtpy.QtCore import Qt

    from napari_swa_imesh._napari._dock import _CheckLabel
    from napari_swa_imesh._napari._mesh_widget import MeshWidget

    widget = MeshWidget(make_napari_viewer())
    labels = {label.text(): label for label in widget.findChildren(_CheckLabel)}
    text = "cut anisotropic voxels into near-cubic cells (quality bound)"
    assert text in labels and labels[text].wordWrap()
    assert widget.subdivide_box.native.accessibleName() == text
    assert widget.subdivide_box.value is True
    qtbot.mouseClick(labels[text], Qt.LeftButton)
    assert widget.subdivide_box.value is False        # clicking the text toggles the box
    assert widget.edges_box.native.text() == "show element edges"    # short texts stay
