"""Screenshots of each step of the napari workflow, from a real napari window.

Run under a display, or under Xvfb on a headless machine::

    xvfb-run -a -s "-screen 0 1280x800x24" python docs/screenshots.py [mosaic] [phantom]

It opens the plugin's two samples, runs samples -> RES -> classify -> mesh -> simulate
through the workflow widget exactly as a user's clicks would (the same methods the buttons
call), and writes PNGs (palette-quantised to stay small) to ``docs/images/``. The window is
a laptop's 1280x800, with the workflow docked through napari's plugin machinery as the menu
docks it.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from napari_swa_imesh._napari._layers import pick
from napari_swa_imesh._napari._mesh_widget import COLOR_BY_QUALITY

OUT = Path(__file__).resolve().parent / "images"
WINDOW = (1280, 800)


def wait(widget, timeout: float = 300.0) -> None:
    """Let the event loop run until the widget's computation has finished."""
    from qtpy.QtWidgets import QApplication

    t0 = time.perf_counter()
    while widget.tasks.busy:
        QApplication.processEvents()
        time.sleep(0.01)
        if time.perf_counter() - t0 > timeout:
            raise TimeoutError(f"{widget.tasks.title} did not finish in {timeout} s")
    settle()
    if widget.tasks.last_error:
        raise RuntimeError(widget.tasks.last_error)


def settle(seconds: float = 0.4) -> None:
    from qtpy.QtWidgets import QApplication

    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        QApplication.processEvents()
        time.sleep(0.02)


def save(viewer, name: str) -> Path:
    """Screenshot of the whole window, quantised to 256 colours (UI art compresses well)."""
    from PIL import Image

    settle()
    pixels = viewer.screenshot(canvas_only=False, flash=False)
    image = Image.fromarray(np.asarray(pixels)[..., :3]).quantize(256, dither=Image.NONE)
    path = OUT / name
    image.save(path, optimize=True)
    print(f"{path.relative_to(OUT.parent.parent)}: {path.stat().st_size // 1024} KB")
    return path


def open_workflow(viewer):
    viewer.window._qt_window.resize(*WINDOW)
    _, flow = viewer.window.add_plugin_dock_widget("napari-swa-imesh", "Segment and mesh")
    return flow


def mosaic_steps(viewer) -> None:
    viewer.open_sample("napari-swa-imesh", "texture_mosaic")
    image, truth = viewer.layers
    truth.visible = False
    flow = open_workflow(viewer)
    save(viewer, "00_window_1280x800.png")         # what a laptop shows before the first step
    samples = flow.samples
    pick(samples.image_combo, image)
    pick(samples.truth_combo, truth)
    samples.per_material_spin.value = 16
    samples.samples_from_truth()
    wait(samples)
    viewer.layers.selection.active = samples.samples_layer()
    viewer.reset_view()
    save(viewer, "01_samples_2d.png")

    flow.tabs.setCurrentIndex(1)
    flow.res.compute()
    wait(flow.res)
    save(viewer, "02_res_2d.png")

    flow.tabs.setCurrentIndex(2)
    pick(flow.classify.truth_combo, truth)
    flow.classify.classify()
    wait(flow.classify)
    samples.samples_layer().visible = False
    save(viewer, "03_classify_2d.png")

    flow.tabs.setCurrentIndex(3)
    flow.mesh.run_mesh()
    wait(flow.mesh)
    viewer.layers[f"{image.name} SWA labels"].visible = False
    flow.mesh.surface_layer.opacity = 0.6       # the texture shows through the elements
    save(viewer, "04_mesh_2d.png")

    # simulate: grass conducts ten times better than brick
    flow.tabs.setCurrentIndex(4)
    flow.simulate.table.set_value(2, "10")
    flow.simulate.run()
    wait(flow.simulate)
    flow.mesh.surface_layer.visible = False
    save(viewer, "08_simulate_2d.png")


def phantom_steps(viewer) -> None:
    from qtpy.QtWidgets import QScrollArea

    viewer.open_sample("napari-swa-imesh", "tissue_phantom")
    image, truth = viewer.layers
    truth.visible = False
    flow = open_workflow(viewer)
    samples = flow.samples
    pick(samples.truth_combo, truth)
    samples.per_material_spin.value = 8
    samples.scale_spin.value = 2
    samples.samples_from_truth()
    wait(samples)
    box = samples.current_samples().boxes[-1]
    viewer.dims.set_point(0, (box.start[0] + 1) * image.scale[0])   # a neighbouring slice
    viewer.reset_view()
    save(viewer, "05_samples_3d.png")

    flow.res.compute()
    wait(flow.res)
    flow.res.choose_scale(2)          # 4-voxel tiles: the grey-matter shell is thin
    flow.tabs.setCurrentIndex(2)
    pick(flow.classify.truth_combo, truth)
    flow.classify.classify()
    wait(flow.classify)

    flow.tabs.setCurrentIndex(3)
    flow.mesh.set_excluded([1])       # leave the CSF out: its box hides the brain
    flow.mesh.run_mesh()
    wait(flow.mesh)
    for layer in viewer.layers:     # by name: a plugin's widget sees layers through a proxy
        layer.visible = layer.name == flow.mesh.surface_layer.name
    viewer.dims.ndisplay = 3
    viewer.reset_view()
    scene = getattr(viewer, "scene", None)          # napari >= 0.9 moved the camera
    camera = scene.camera if scene is not None else viewer.camera
    camera.angles = (-25, 40, 135)
    camera.zoom *= 0.9
    save(viewer, "06_mesh_3d.png")
    flow.mesh.color_combo.value = "material"
    save(viewer, "07_mesh_3d_materials.png")

    # see inside: the whole tetrahedra above the middle plane, coloured by quality
    flow.mesh.color_combo.value = COLOR_BY_QUALITY
    clip = flow.mesh.clip
    clip.axis_combo.value = 0                 # z: the slider starts in the middle
    clip.keep_combo.value = "above"
    clip.enable_box.value = True
    flow.mesh.clip_box.set_open(True)
    settle()
    flow.mesh.findChild(QScrollArea).ensureWidgetVisible(flow.mesh.clip_box)
    camera.zoom *= 1.1
    save(viewer, "09_mesh_3d_clipped.png")

    # simulate: electric conduction across the head along x (S/m, as in EEG head models),
    # so the CSF is meshed too: the brain alone touches no face of the box
    clip.enable_box.value = False
    flow.mesh.set_excluded([])
    flow.mesh.run_mesh()
    wait(flow.mesh)
    flow.tabs.setCurrentIndex(4)
    simulate = flow.simulate
    for label, k in ((1, "1.79"), (2, "0.33"), (3, "0.14")):
        simulate.table.set_value(label, k)
    for axis in "yz":
        simulate.axis_boxes[axis].value = False
    # P1 on the 1.65M tetrahedra as shown (the default would take P2: minutes, not one)
    simulate.order_combo.value = "P1 (linear)"
    simulate.run()
    wait(simulate, timeout=900)
    flow.mesh.surface_layer.visible = False
    # the whole tetrahedra below the middle plane, seen from above: the field on the cut
    field_clip = simulate.clip
    field_clip.axis_combo.value = 0
    field_clip.keep_combo.value = "below"
    field_clip.enable_box.value = True
    viewer.reset_view()
    camera.set_view_direction((-1, 0.5, 0.4), (0, -1, 0))
    camera.zoom *= 0.8
    simulate.clip_box.set_open(True)
    settle()
    simulate.findChild(QScrollArea).ensureWidgetVisible(simulate.clip_box)
    save(viewer, "10_simulate_3d_clipped.png")


def main(argv: list[str]) -> int:
    """Every screenshot, or those of the samples named: ``mosaic``, ``phantom``."""
    import napari

    OUT.mkdir(parents=True, exist_ok=True)
    chosen = {"mosaic": mosaic_steps, "phantom": phantom_steps}
    for steps in [chosen[name] for name in argv] or chosen.values():
        viewer = napari.Viewer(show=True)
        try:
            steps(viewer)
        finally:
            viewer.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
