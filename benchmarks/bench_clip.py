"""The mesh tab's clip: time per slider move on a mesh of about a million tetrahedra.

Run:  python benchmarks/bench_clip.py [--quick] [--napari]

The mesh: IMESH of smooth random regions (3 materials) on a 48 x 80 x 80 volume with
2:1:1 voxels, 1.28M tetrahedra (``--quick``: 24 x 40 x 40). Reported, per move of the
plane (median and worst of 10 positions per axis; the first move on an axis apart, since
it caches the element extents on that axis):

* ``MeshClipper.surface`` (what the widget runs): masks and a sort of the faces of the
  cut elements only;
* peers on the same kept set: re-pairing the faces of the kept elements with numpy
  (``shown_faces``) per move; pyvista ``extract_cells`` + ``extract_surface``; pyvista's
  crinkle ``clip`` + ``extract_surface``.

``--napari`` (needs a display; ``xvfb-run -a`` on a headless machine) also times the
widget's redraw of its Surface layer per move (``MeshWidget.refresh_surface``: the layer's
data and colours) and the next frame (``viewer.screenshot``), which under Xvfb is
software OpenGL: a real GPU draws it far faster.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:7.1f} ms"


def _time(fn, *args, **kwargs) -> tuple[float, object]:
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - t, out


def compute(mesh) -> None:
    from napari_swa_imesh.mesh import MeshClipper, mesh_surface, shown_faces

    seconds, surface = _time(mesh_surface, mesh)
    print(f"mesh_surface (once per mesh, in the worker): {_ms(seconds)}")
    clipper = MeshClipper(mesh, shown=(surface["faces"], surface["owners"]))
    for axis in range(3):
        lo, hi = clipper.extent(axis)
        first, _ = _time(clipper.surface, axis, (lo + hi) / 2)
        moves = [_time(clipper.surface, axis, p) for p in np.linspace(lo, hi, 12)[1:-1]]
        times = [t for t, _ in moves]
        faces = int(np.median([out["n_faces"] for _, out in moves]))
        print(f"MeshClipper.surface axis {axis}: first {_ms(first)}, then median "
              f"{_ms(np.median(times))}, worst {_ms(max(times))} ({faces} faces)")
    lo, hi = clipper.extent(0)
    kept = clipper.kept(0, (lo + hi) / 2)
    seconds, _ = _time(shown_faces, mesh.cells[kept], mesh.material[kept])
    print(f"peer: shown_faces of the kept elements per move: {_ms(seconds)}")
    try:
        import pyvista  # noqa: F401
    except ImportError:
        print("pyvista not installed: its peers skipped")
        return
    seconds, grid = _time(mesh.to_pyvista)
    print(f"Mesh.to_pyvista (once): {_ms(seconds)}")
    seconds, _ = _time(lambda: grid.extract_cells(kept).extract_surface(algorithm=None))
    print(f"peer: pyvista extract_cells + extract_surface per move: {_ms(seconds)}")
    seconds, _ = _time(lambda: grid.clip(normal="z", origin=(0, 0, (lo + hi) / 2), invert=True,
                                         crinkle=True).extract_surface(algorithm=None))
    print(f"peer: pyvista crinkle clip + extract_surface per move: {_ms(seconds)}")


def in_napari(labels, spacing) -> None:
    from qtpy.QtWidgets import QApplication

    import napari
    from napari_swa_imesh._napari._mesh_widget import (
        COLOR_BY_MATERIAL,
        COLOR_BY_QUALITY,
        MeshWidget,
    )

    viewer = napari.Viewer(show=True)
    viewer.window._qt_window.resize(1500, 940)
    layer = viewer.add_labels(labels, scale=spacing)
    widget = MeshWidget(viewer)
    widget.select_labels(layer)
    widget.set_excluded([])
    widget.checks_box.value = False
    widget.run_mesh()
    while widget.tasks.busy:
        QApplication.processEvents()
        time.sleep(0.01)
    viewer.dims.ndisplay = 3
    clip = widget.clip
    clip.enable_box.value = True
    for axis, colour in ((0, COLOR_BY_QUALITY), (1, COLOR_BY_QUALITY), (2, COLOR_BY_QUALITY),
                         (0, COLOR_BY_MATERIAL)):
        widget.color_combo.value = colour
        clip.axis_combo.value = axis
        QApplication.processEvents()
        time.sleep(0.1)
        QApplication.processEvents()
        lo, hi = clip.clipper.extent(axis)
        redraw, frame = [], []
        for p in np.linspace(lo, hi, 8)[1:-1]:
            with clip.position_slider.changed.blocked():
                clip.position_slider.value = p
            redraw.append(_time(widget.refresh_surface)[0])
            frame.append(_time(viewer.screenshot, canvas_only=True, flash=False)[0])
        print(f"napari axis {axis}, {colour.split()[0]}: layer redraw median "
              f"{_ms(np.median(redraw))} (worst {_ms(max(redraw))}), next frame median "
              f"{_ms(np.median(frame))}")
    viewer.close()


def main() -> int:
    from napari_swa_imesh.data import blob_labels
    from napari_swa_imesh.mesh import mesh_labels

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--napari", action="store_true")
    args = parser.parse_args()
    shape = (24, 40, 40) if args.quick else (48, 80, 80)
    spacing = (2.0, 1.0, 1.0)
    labels = blob_labels(shape, 3, seed=1, sigma=4.0).astype(np.uint8) + 1
    seconds, mesh = _time(mesh_labels, labels, spacing=spacing)
    print(f"{shape} labels, spacing {spacing}: {mesh.n_cells} tetrahedra, "
          f"{len(mesh.points)} vertices ({seconds:.1f} s to mesh)")
    compute(mesh)
    if args.napari:
        in_napari(labels, spacing)
    return 0


if __name__ == "__main__":
    sys.exit(main())
