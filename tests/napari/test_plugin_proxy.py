"""Widgets docked through napari's plugin machinery see the viewer through a proxy.

napari hands a plugin's widget a ``PublicOnlyProxy`` of the viewer, so the layers the widget
looks up are proxies too and ``type(layer).__name__`` is ``"PublicOnlyProxy"``. Reported
by the screenshots at 1280x800 (docked as the menu docks them): meshing again added a second
mesh layer ``... mesh [1]`` instead of updating the first, and classifying again a second
labels layer. Found while proving the plain install path (tests/packaging).
"""

from napari.layers import Labels, Surface
from swa_napari_helpers import wait_idle


def test_running_again_updates_the_layers_in_place(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    viewer.open_sample("napari-swa-imesh", "texture_mosaic")
    _, flow = viewer.window.add_plugin_dock_widget("napari-swa-imesh", "Segment and mesh")
    assert flow.viewer is not viewer                   # the proxy this test is about
    flow.samples.truth_combo.value = viewer.layers[-1]
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    for _ in range(2):
        flow.classify.classify()
        wait_idle(qtbot, flow.classify)
        flow.mesh.run_mesh()
        wait_idle(qtbot, flow.mesh)
    names = [layer.name for layer in viewer.layers]
    assert [isinstance(layer, Labels) and "SWA labels" in layer.name
            for layer in viewer.layers].count(True) == 1, names
    assert [isinstance(layer, Surface) for layer in viewer.layers].count(True) == 1, names
