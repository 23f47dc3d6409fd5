"""Helpers shared by the widget tests (imported by name: this folder is on sys.path)."""

from __future__ import annotations

import numpy as np

# small enough that the whole napari suite runs in a few minutes on two shared cores, large
# enough that the grey-matter shell of the phantom still holds sample blocks
PHANTOM_SHAPE = (48, 64, 64)


def add_layer_data(viewer, layer_data):
    """Add napari LayerData tuples (what a sample-data command returns) to `viewer`."""
    return [getattr(viewer, f"add_{kind}")(data, **kwargs) for data, kwargs, kind in layer_data]


class Notifications:
    """napari notifications dispatched during a test (errors, warnings, infos)."""

    def __init__(self):
        from napari.utils.notifications import notification_manager

        self.manager = notification_manager
        self.start = len(notification_manager.records)

    @property
    def all(self):
        return self.manager.records[self.start:]

    def messages(self, severity: str | None = None) -> list[str]:
        return [str(n.message) for n in self.all
                if severity is None or str(n.severity).lower().endswith(severity)]

    @property
    def errors(self) -> list[str]:
        return self.messages("error")


def wait_idle(qtbot, *widgets, timeout=60_000):
    """Wait until every widget's TaskPanel has finished its computation."""
    qtbot.waitUntil(lambda: all(not w.tasks.busy for w in widgets), timeout=timeout)


def rect(r0, c0, r1, c1):
    """Rectangle covering pixels [r0, r1) x [c0, c1) (pixel edges at half integers)."""
    return np.array([[r0, c0], [r0, c1], [r1, c1], [r1, c0]], float) - 0.5


def draw_boxes(samples, boxes: dict[str, list]):
    """A new samples layer of `samples` (a SamplesWidget) holding, per material name in
    order, its rectangles (:func:`rect`); the materials replace the table's. The layer."""
    layer = samples.new_samples_layer()
    samples.set_materials([])
    materials = [samples.add_material(name) for name in boxes]
    for material, rects in zip(materials, boxes.values()):
        samples.select_material(material.label)
        layer.add_rectangles(rects)
    return layer
