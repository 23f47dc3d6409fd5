"""Samples widget: draw sample boxes per material, check them, import/export, from a truth."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import Container, SpinBox
from qtpy.QtCore import Signal
from qtpy.QtGui import QColor
from qtpy.QtWidgets import QFileDialog, QHeaderView, QTableWidget, QTableWidgetItem, QWidget

from ..segmentation import Material, Samples, load_samples, samples_from_truth, save_samples
from . import _samples_layer as sl
from ._dock import button, fit_dock, group, scroll_body, side_by_side, wrapped_label
from ._help import explain_terms
from ._layers import default_color, layer_picker, pick
from ._materials import MaterialTable
from ._tasks import TaskPanel, notify_error, notify_info, notify_warning

if TYPE_CHECKING:
    import napari

__all__ = ["SamplesWidget"]


class SamplesWidget(QWidget):
    """Draw, check, import and export the sample boxes of each material.

    Parameters
    ----------
    napari_viewer : napari.viewer.Viewer

    Signals
    -------
    samples_layer_changed(object)
        The samples layer in use (a napari Shapes layer) changed.
    """

    samples_layer_changed = Signal(object)

    def __init__(self, napari_viewer: napari.viewer.Viewer, parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self._watched = None          # samples layer whose events we listen to
        self.report = None            # BoxReport of the samples layer, per shape
        self.image_combo = layer_picker(self.viewer, "Image", label="image")
        self.samples_combo = layer_picker(self.viewer, "Shapes", label="samples",
                                          accept=sl.is_samples_layer)
        self.new_button = button("New samples layer", self.new_samples_layer,
                                 "Add a Shapes layer over the image and start drawing "
                                 "rectangles (one per sample box).")
        self.material_table = MaterialTable()
        self.add_material_button = button("Add material", self.add_material)
        self.remove_material_button = button("Remove material", self._on_remove_material)
        self.assign_button = button("Assign to selected boxes", self.assign_selected,
                                    "Give the selected rectangles the selected material.")
        self.depth_spin = SpinBox(
            label="depth (slices, 3-D)", min=1, max=4096, value=sl.DEFAULT_DEPTH,
            tooltip="3-D: slices a rectangle spans, centred on the slice it is drawn on. "
                    "Applies to new boxes and to selected boxes.")
        self.scale_spin = SpinBox(
            label="check at scale j", min=0, max=16, value=3,
            tooltip="Boxes shorter than one tile of 2^j pixels along some axis give no "
                    "training tile at scale j and are flagged; so are the boxes of a material "
                    "whose largest box holds no window of 2^j+1 px (the recommended "
                    "method's). Follows the scale chosen on the RES tab and the classify tab's.")
        self.box_table = _box_table()
        self.summary = wrapped_label()
        self.import_button = button("Import JSON...", self._on_import_clicked)
        self.export_button = button("Export JSON...", self._on_export_clicked)
        self.truth_combo = layer_picker(self.viewer, "Labels", label="truth")
        self.per_material_spin = SpinBox(label="boxes per material", min=1, max=64, value=4)
        self.truth_button = button("Samples from truth", self.samples_from_truth,
                                   "Boxes on the largest homogeneous blocks of each material "
                                   "of a ground-truth Labels layer (its 2^d-tree).")
        self.tasks = TaskPanel()

        layout = scroll_body(self)
        layout.addWidget(Container(widgets=[self.image_combo, self.samples_combo,
                                            self.new_button]).native)
        layout.addWidget(group("Materials (select one, then draw rectangles)", [
            self.material_table, side_by_side(self.add_material_button,
                                              self.remove_material_button),
            self.assign_button]))
        layout.addWidget(Container(widgets=[self.depth_spin, self.scale_spin]).native)
        layout.addWidget(group("From a ground truth", [Container(widgets=[
            self.truth_combo, self.per_material_spin, self.truth_button]).native]))
        layout.addWidget(self.tasks)
        layout.addWidget(self.summary.native)      # the check's result above the fold
        layout.addWidget(self.box_table, 1)
        layout.addWidget(side_by_side(self.import_button, self.export_button))
        fit_dock(self)
        self.material_table.edited.connect(self._store_materials)
        self.material_table.itemSelectionChanged.connect(self._on_current_material)
        self.depth_spin.changed.connect(self._on_depth_changed)
        self.scale_spin.changed.connect(self.check_boxes)
        self.box_table.cellClicked.connect(self._on_box_clicked)
        self.samples_combo.changed.connect(self._on_samples_layer_selected)
        self.image_combo.changed.connect(self.check_boxes)
        self._on_samples_layer_selected()
        explain_terms(self)

    # -- layers ----------------------------------------------------------------------------
    def image_layer(self):
        return self.image_combo.value

    def samples_layer(self):
        return self.samples_combo.value

    def new_samples_layer(self):
        """Add an empty samples layer over the selected image and start rectangle drawing.

        Returns the layer, or None (with a notification) when there is no image.
        """
        image = self.image_layer()
        if image is None:
            notify_error("no image layer to sample: open an image (File > Open or File > "
                         "Open Sample) and select it in the samples widget.")
            return None
        if image.ndim not in (2, 3):
            notify_error(f"image layer {image.name!r} has {image.ndim} dimensions; SWA works "
                         "on 2-D and 3-D grey-level images, so pick or make one.")
            return None
        materials = self.materials() or [Material(1, "material 1", default_color(1)),
                                         Material(2, "material 2", default_color(2))]
        layer = sl.new_samples_layer(self.viewer, image, materials, depth=self.depth_spin.value)
        pick(self.samples_combo, layer)
        self._on_samples_layer_selected()
        self.viewer.layers.selection.active = layer
        layer.mode = "add_rectangle"
        return layer

    def _on_samples_layer_selected(self, *_) -> None:
        layer = self.samples_layer()
        if self._watched is not None and self._watched is not layer:
            self._watched.events.data.disconnect(self._on_shapes_changed)
        if layer is not None and layer is not self._watched:
            if "label" not in layer.features and layer.ndim in (2, 3):
                first = (self.materials() or [Material(1, "material 1", default_color(1))])[0]
                sl.adopt_layer(layer, first, depth=self.depth_spin.value if layer.ndim == 3
                               else 1)
            layer.events.data.connect(self._on_shapes_changed)
            image_name = layer.metadata.get(sl.SAMPLES_KEY)
            if image_name and image_name in self.viewer.layers:
                pick(self.image_combo, self.viewer.layers[image_name])
            chosen = sl.chosen_scale(layer, self.image_layer())
            if chosen is not None:        # only a scale chosen on these very boxes
                self.scale_spin.value = chosen
        self._watched = layer
        self.material_table.set_materials(sl.layer_materials(layer) if layer is not None else [])
        self.check_boxes()
        self.samples_layer_changed.emit(layer)

    def _on_shapes_changed(self, event=None) -> None:
        action = str(getattr(event, "action", "")) if event is not None else ""
        if action.endswith("ing"):      # adding/changing/removing: wait for the final event
            return
        self.check_boxes()

    # -- materials -------------------------------------------------------------------------
    def materials(self) -> list[Material]:
        """The material list (label, name, colour) as library Materials."""
        return list(self.material_table.materials)

    def set_materials(self, materials: list[Material]) -> None:
        """Replace the material list (and the samples layer's copy of it)."""
        self.material_table.set_materials(materials)
        self._store_materials()

    def _store_materials(self) -> None:
        layer = self.samples_layer()
        if layer is not None:
            sl.set_layer_materials(layer, self.materials())
            self._on_current_material()
            self.check_boxes()

    def add_material(self, name: str | None = None) -> Material:
        """Append a material with the next free label."""
        materials = self.materials()
        label = max([m.label for m in materials], default=0) + 1
        material = Material(label, name or f"material {label}", default_color(label))
        self.set_materials(materials + [material])
        self.material_table.select_label(label)
        return material

    def _on_remove_material(self) -> None:
        row = self.material_table.currentRow()
        materials = self.materials()
        if row < 0 or not materials:
            return
        label = materials[row].label
        layer = self.samples_layer()
        if layer is not None and "label" in layer.features and \
                (layer.features["label"].astype(int) == label).any():
            notify_error(f"material {materials[row].name!r} still has boxes; delete them or "
                         "assign them another material first.")
            return
        self.set_materials(materials[:row] + materials[row + 1:])

    def current_material(self) -> Material | None:
        return self.material_table.current()

    def select_material(self, label: int) -> None:
        """Make material `label` the one new rectangles get."""
        self.material_table.select_label(label)

    def _on_current_material(self) -> None:
        layer, material = self.samples_layer(), self.current_material()
        if layer is not None and material is not None:
            sl.set_current_material(layer, material, depth=self._depth_for(layer))

    def _depth_for(self, layer) -> int:
        return self.depth_spin.value if layer.ndim == 3 else 1

    def assign_selected(self) -> None:
        """Give the selected rectangles the current material."""
        layer, material = self.samples_layer(), self.current_material()
        if layer is None or material is None or not layer.selected_data:
            notify_warning("select rectangles in the samples layer (select tool) and a "
                           "material in the table, then assign.")
            return
        features = layer.features.copy()
        rows = sorted(layer.selected_data)
        features.loc[rows, "label"] = material.label
        features.loc[rows, "name"] = material.name
        layer.features = features
        self.check_boxes()

    def _on_depth_changed(self, value: int) -> None:
        layer = self.samples_layer()
        if layer is None or layer.ndim != 3:
            return
        self._on_current_material()
        if layer.selected_data:
            features = layer.features.copy()
            features.loc[sorted(layer.selected_data), "depth"] = int(value)
            layer.features = features
            self.check_boxes()

    def _say(self, text: str) -> None:
        self.summary.value = text

    # -- checks ----------------------------------------------------------------------------
    def check_boxes(self, *_):
        """Recompute every box and its flags; show them in the table and on the canvas.

        Returns the BoxReport (None without an image or samples layer).
        """
        layer, image = self.samples_layer(), self.image_layer()
        self.report = None
        if layer is None or image is None:
            self.box_table.setRowCount(0)
            self._say("Pick an image and create or pick a samples layer."
                                 if image is None or layer is None else "")
            return None
        if layer.ndim != image.ndim:
            self.box_table.setRowCount(0)
            self._say(f"The samples layer is {layer.ndim}-D but the image is "
                                 f"{image.ndim}-D; pick matching layers.")
            return None
        try:
            report = sl.layer_report(layer, image, scale=self.scale_spin.value)
        except ValueError as exc:
            self._say(str(exc))
            return None
        self.report = report
        sl.restyle(layer, report)
        names = layer.features["name"].tolist() if "name" in layer.features else []
        self.box_table.setRowCount(len(report.boxes))
        for i, box in enumerate(report.boxes):
            cells = [names[i] if i < len(names) else "",
                     "" if box is None else str(list(box.start)),
                     "" if box is None else str(list(box.stop)), report.flag_text(i)]
            for column, text in enumerate(cells):
                item = QTableWidgetItem(text)
                if report.flags[i]:
                    item.setForeground(QColor("#ff8c69"))
                self.box_table.setItem(i, column, item)
        n_flagged = sum(bool(f) for f in report.flags)
        limit = sl.report_window_limit(layer, report, self.scale_spin.value)
        self._say(
            f"{len(report.boxes)} box(es), {n_flagged} flagged"
            + (f"; {len(report.blocking)} cannot be used until moved or deleted"
               if report.blocking else "")
            + (f". Recommended method: {limit[1]}." if limit is not None else ""))
        if image.ndim == 3:
            sl.update_extent_overlay(self.viewer, layer, image, report)
        return report

    def _on_box_clicked(self, row: int, column: int) -> None:
        layer = self.samples_layer()
        if layer is None or row >= len(layer.data):
            return
        layer.selected_data = {row}
        if layer.ndim == 3 and self.report is not None and self.report.boxes[row] is not None:
            axis = self.report.thickness_axis[row]
            world = layer.data[row][0] * layer.scale + layer.translate
            self.viewer.dims.set_point(axis, float(world[axis]))

    def set_scale(self, scale: int) -> None:
        """Check boxes at `scale` (the workflow calls this when a RES is chosen)."""
        self.scale_spin.value = int(scale)

    # -- files -----------------------------------------------------------------------------
    def current_samples(self) -> Samples:
        """The library Samples of the samples layer (ValueError says what to fix)."""
        layer, image = self.samples_layer(), self.image_layer()
        if image is None:
            raise ValueError("no image layer selected; open an image and pick it in the "
                             "samples widget.")
        if layer is None:
            raise ValueError("no samples layer; press 'New samples layer' and draw boxes, or "
                             "import a samples file.")
        samples, _ = sl.samples_from_layer(layer, image, scale=self.scale_spin.value)
        return samples

    def export_samples(self, path) -> None:
        """Write the samples JSON of the command line (replacing an existing file)."""
        try:
            save_samples(self.current_samples(), path, force=True)
        except (ValueError, OSError) as exc:
            notify_error(f"could not export the samples: {exc}")
            return
        notify_info(f"samples written to {path}")

    def import_samples(self, path) -> None:
        """Read a samples JSON into a samples layer over the selected image."""
        image = self.image_layer()
        if image is None:
            notify_error("no image layer to put the samples on: open the image first and "
                         "pick it in the samples widget.")
            return
        try:
            samples = load_samples(path)
            samples.check(image_array_shape(image))
        except (ValueError, OSError) as exc:
            notify_error(f"could not import {path}: {exc}")
            return
        self._put(samples)

    def _put(self, samples: Samples) -> None:
        image = self.image_layer()
        layer = self.samples_layer()
        if layer is None or layer.ndim != image.ndim:
            layer = self.new_samples_layer()
        materials = [Material(m.label, m.name, m.color or default_color(m.label))
                     for m in samples.materials]
        samples = Samples(materials, samples.boxes)
        sl.put_boxes(layer, image, samples, thickness_axis=self._thickness_axis(image))
        self.material_table.set_materials(materials)
        self._on_current_material()
        self.check_boxes()

    def _thickness_axis(self, image) -> int:
        """Axis across the screen in 2-D view (where rectangles are flat), 0 otherwise."""
        if image.ndim != 3 or self.viewer.dims.ndisplay != 2:
            return 0
        hidden = [a for a in self.viewer.dims.not_displayed if a < 3]
        return hidden[0] if len(hidden) == 1 else 0

    def _on_import_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Import samples", "", "Samples (*.json)")
        if path:
            self.import_samples(path)

    def _on_export_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export samples", "samples.json",
                                              "Samples (*.json)")
        if path:
            self.export_samples(path)

    # -- from a truth ----------------------------------------------------------------------
    def samples_from_truth(self):
        """Boxes on the largest homogeneous blocks of the truth layer (in a worker)."""
        truth, image = self.truth_combo.value, self.image_layer()
        if truth is None or image is None:
            notify_error("pick an image and a ground-truth Labels layer to take samples from.")
            return None
        shape = image_array_shape(image)
        if truth.data.shape != shape or not np.allclose(truth.scale, image.scale):
            notify_error(f"the truth {truth.name!r} (shape {truth.data.shape}) does not match "
                         f"the image {image.name!r} (shape {shape}) in shape and scale; pick "
                         "the truth of this image.")
            return None
        data = np.asarray(truth.data)
        scale, per_material = self.scale_spin.value, self.per_material_spin.value
        names = {int(k): str(v) for k, v in truth.metadata.get("material_names", {}).items()}

        def steps():
            yield 0, 1, "largest homogeneous blocks of the truth"
            samples = samples_from_truth(data, scale=scale, per_material=per_material,
                                         names=names or None)
            yield 1, 1, "done"
            return samples

        return self.tasks.run(steps, title="Samples from truth", on_result=self._put)


def image_array_shape(image_layer) -> tuple[int, ...]:
    """Shape of the image's pixel array (level 0 when multiscale)."""
    data = image_layer.data[0] if image_layer.multiscale else image_layer.data
    return tuple(data.shape)


def _box_table() -> QTableWidget:
    table = QTableWidget(0, 4)
    table.setHorizontalHeaderLabels(["material", "start", "stop", "flags"])
    table.horizontalHeader().setSectionResizeMode(3, QHeaderView.Stretch)
    table.setEditTriggers(QTableWidget.NoEditTriggers)
    table.setSelectionBehavior(QTableWidget.SelectRows)
    return table
