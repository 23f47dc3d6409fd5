"""Every dock fits a screen: its content scrolls and its plots shrink instead of growing the
napari window.

The reported case: a new user docked the workflow and the four step widgets, napari grew to
2363 px on a 1024-px screen, the canvas became a 230-px strip, and napari kept that size at
the next start. A dock's minimum height adds to the window's, so each dock must be able to
shrink well below a 1080-px screen, and all five docked together must still fit an 800x600
screen (the tests' Xvfb screen is now a 1280x800 laptop's: test_laptop_screen.py).
Measured before the docks scrolled: minimum heights of 585, 328, 682 and 595 px for the
four step docks, and the window grew from 630 to 2376 px; now every dock (the Simulate
dock too) can shrink to 68-95 px and the window keeps its size.
"""

import pytest
from qtpy.QtWidgets import QApplication, QScrollArea
from swa_napari_helpers import wait_idle

PLUGIN = "napari-swa-imesh"
DOCKS = ("Segment and mesh", "Sample boxes", "RES plots", "Classify (SWA)", "Mesh (IMESH)",
         "Simulate (k_eff)")
MAX_HINT = 900          # px: room for napari's menus and title bar on a 1080-px screen
SMALL_SCREEN_HEIGHT = 600


def _fill(widgets, truth, qtbot):
    """Give every dock its largest content: samples, RES plots, a mesh histogram, k_eff."""
    flow, samples, res, _, mesh, simulate = widgets
    for panel in (flow.samples, samples):
        panel.truth_combo.value = truth
        panel.samples_from_truth()
        wait_idle(qtbot, panel)
    for panel in (flow.res, res):
        panel.compute()
        wait_idle(qtbot, panel)
    for panel in (flow.mesh, mesh):
        panel.select_labels(truth)
        panel.run_mesh()
        wait_idle(qtbot, panel)
    for panel, mesher in ((flow.simulate, flow.mesh), (simulate, mesh)):
        panel.select_mesh(mesher.surface_layer)
        panel.run()
        wait_idle(qtbot, panel)
        assert panel.result is not None


def test_docks_fit_a_1080_px_screen(make_napari_viewer, qtbot):
    from napari_swa_imesh._napari._sample_data import make_texture_mosaic

    viewer = make_napari_viewer(show=True)
    for data, kwargs, kind in make_texture_mosaic():
        getattr(viewer, f"add_{kind}")(data, **kwargs)
    truth = viewer.layers[-1]
    window = viewer.window._qt_window
    screen = QApplication.primaryScreen().availableGeometry()
    QApplication.processEvents()
    before = window.height()
    docked = [viewer.window.add_plugin_dock_widget(PLUGIN, name) for name in DOCKS]
    widgets = [widget for _, widget in docked]
    bodies = [widget.findChild(QScrollArea).widget() for widget in widgets[1:]]
    empty = [body.minimumSizeHint().width() for body in bodies]
    _fill(widgets, truth, qtbot)
    QApplication.processEvents()
    for (dock, _widget), name in zip(docked, DOCKS):
        hint, minimum = dock.sizeHint().height(), dock.minimumSizeHint().height()
        print(f"{name}: sizeHint {hint} px, minimumSizeHint {minimum} px")
        assert hint <= MAX_HINT and minimum <= MAX_HINT, name
    for widget in widgets[1:]:      # the workflow's tabs are these very widgets
        assert widget.minimumSizeHint().height() < 200
    # long messages wrap instead of widening the dock (magicgui sizes labels to their text)
    for body, width in zip(bodies, empty):
        print(f"content at least {width} px wide, {body.minimumSizeHint().width()} px filled")
        assert body.minimumSizeHint().width() <= max(width, 420)
    print(f"window {before} -> {window.height()} px (minimum "
          f"{window.minimumSizeHint().height()} px) on a screen of {screen.height()} px")
    assert window.height() == before               # docking did not grow the window
    assert window.minimumSizeHint().height() <= min(screen.height(), SMALL_SCREEN_HEIGHT)


@pytest.mark.parametrize("kind", ["res", "mesh"])
def test_plots_grow_with_the_dock_from_a_modest_minimum(make_napari_viewer, kind):
    from napari_swa_imesh._napari._mesh_widget import MeshWidget
    from napari_swa_imesh._napari._res_widget import ResWidget

    widget = (ResWidget if kind == "res" else MeshWidget)(make_napari_viewer())
    canvas = widget.plot.canvas
    assert canvas.minimumHeight() <= 360
    assert canvas.sizePolicy().verticalPolicy() == canvas.sizePolicy().Policy.Expanding
