"""Simulate widget: steady diffusion on an IMESH mesh layer, k_eff per axis, the field shown.

Thin: the conductivity table is a view of a list of records, the computation is
:func:`napari_swa_imesh.simulate.simulate_steps` in the task panel's worker, and the result
is drawn as a Surface coloured by the potential plus a figure with the colour bar and each
k_eff inside its Reuss-Voigt interval.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, PushButton
from qtpy.QtCore import Qt, Signal
from qtpy.QtWidgets import QFileDialog, QLabel, QTableWidget, QTableWidgetItem, QWidget

from ..mesh import shown_faces
from ..simulate import simulate_steps, write_field
from ._dock import scroll_body, side_by_side, wrapped_label
from ._layers import MESH_KEY, layer_picker, pick
from ._plots import ThemedFigure
from ._tasks import TaskPanel, notify_error, notify_info

if TYPE_CHECKING:
    import napari
    from matplotlib.figure import Figure

    from ..simulate import SimulationResult

__all__ = ["SimulateWidget", "Conductivity", "FIELD_KEY"]

FIELD_KEY = "swa_imesh_field"
ORDERS = {"P1 (linear)": 1, "P2 (quadratic, more accurate)": 2}
COLORMAP = "turbo"


@dataclass(frozen=True)
class Conductivity:
    """One row of the table: a material and the text of its conductivity."""

    label: int
    name: str
    text: str = "1"


def parse_conductivity(text: str) -> float | list[float]:
    """``"2.5"`` -> 2.5; ``"1, 2, 3"`` -> the diagonal in x, y(, z) order.

    Raises
    ------
    ValueError
        Text that is not a number or a comma list of numbers.
    """
    try:
        numbers = [float(t) for t in text.replace(";", ",").split(",") if t.strip()]
    except ValueError:
        numbers = []
    if not numbers:
        raise ValueError(f"conductivity {text!r} is not a number (or a comma list of "
                         "numbers for the diagonal in x, y, z order).")
    return numbers[0] if len(numbers) == 1 else numbers


class ConductivityTable(QTableWidget):
    """Material | name | conductivity; the records list is the data, the table its view."""

    edited = Signal()

    def __init__(self, parent: QWidget | None = None):
        super().__init__(0, 3, parent)
        self.setHorizontalHeaderLabels(["material", "name", "conductivity k"])
        self.horizontalHeader().setStretchLastSection(True)
        self.verticalHeader().setVisible(False)
        self.setMaximumHeight(150)
        self.setToolTip("Conductivity (or diffusivity) per material: a positive number, or "
                        "one number per axis (x, y in 2-D; x, y, z in 3-D) for a diagonal "
                        "tensor.")
        self.records: list[Conductivity] = []
        self.itemChanged.connect(self._on_item_changed)

    def set_records(self, records: list[Conductivity]) -> None:
        self.records = list(records)
        self.blockSignals(True)
        self.setRowCount(len(self.records))
        for row, record in enumerate(self.records):
            for col, text in enumerate((str(record.label), record.name, record.text)):
                item = QTableWidgetItem(text)
                if col < 2:
                    item.setFlags(item.flags() & ~Qt.ItemIsEditable)
                self.setItem(row, col, item)
        self.blockSignals(False)

    def set_value(self, label: int, text: str) -> None:
        """Set one material's conductivity text (as an edit in the table would)."""
        self.set_records([Conductivity(r.label, r.name, text) if r.label == label else r
                          for r in self.records])
        self.edited.emit()

    def conductivity(self) -> dict[int, float | list[float]]:
        """{label: value} of every row; ValueError names a row that is not a number."""
        return {r.label: parse_conductivity(r.text) for r in self.records}

    def _on_item_changed(self, item: QTableWidgetItem) -> None:
        if item.column() == 2 and item.row() < len(self.records):
            record = self.records[item.row()]
            self.records[item.row()] = Conductivity(record.label, record.name, item.text())
            self.edited.emit()


class SimulateWidget(QWidget):
    """Effective conductivity of the image box from a mesh layer; field on the surface.

    Signals
    -------
    simulated(object)
        The :class:`SimulationResult` of a finished run.
    """

    simulated = Signal(object)

    def __init__(self, napari_viewer: "napari.viewer.Viewer", parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.result: SimulationResult | None = None
        self.field_layer = None
        self.mesh_combo = layer_picker(self.viewer, "Surface", label="mesh",
                                       accept=lambda layer: MESH_KEY in layer.metadata)
        self.table = ConductivityTable()
        self.order_combo = ComboBox(label="elements", choices=list(ORDERS))
        self.axis_boxes = {a: CheckBox(text=a, value=True) for a in "xyz"}
        self.show_combo = ComboBox(label="show potential of", choices=["x", "y", "z"])
        self.run_button = PushButton(text="Simulate")
        self.export_button = PushButton(text="Export field...", enabled=False,
                                        tooltip="Write the mesh with potential and flux per "
                                                "axis (.vtu or .xdmf, for ParaView).")
        self.summary = wrapped_label()
        self.summary.native.setTextInteractionFlags(Qt.TextSelectableByMouse)
        self.plot = ThemedFigure(self.viewer, self._draw_figure, min_height=160)
        self.tasks = TaskPanel()

        layout = scroll_body(self)
        layout.addWidget(Container(widgets=[self.mesh_combo]).native)
        layout.addWidget(QLabel("conductivity per material"))
        layout.addWidget(self.table)
        layout.addWidget(Container(widgets=[self.order_combo]).native)
        layout.addWidget(QLabel("k_eff along (x = column, y = row, z = plane)"))
        layout.addWidget(side_by_side(*self.axis_boxes.values()))
        layout.addWidget(Container(widgets=[self.show_combo, self.run_button]).native)
        layout.addWidget(self.tasks)
        layout.addWidget(self.summary.native)
        layout.addWidget(self.plot, 1)
        layout.addWidget(self.export_button.native)
        self.mesh_combo.changed.connect(self._refresh_materials)
        self.show_combo.changed.connect(self.show_field)
        self.run_button.changed.connect(self.run)
        self.export_button.changed.connect(self._on_export_clicked)
        self._refresh_materials()

    @property
    def figure(self) -> "Figure":
        return self.plot.figure

    # -- inputs ----------------------------------------------------------------------------
    def select_mesh(self, layer) -> None:
        """Simulate on this mesh layer next (the workflow passes the new mesh)."""
        pick(self.mesh_combo, layer)
        self._refresh_materials()

    def _refresh_materials(self, *_) -> None:
        layer = self.mesh_combo.value
        if layer is None:
            self.table.set_records([])
            return
        mesh = layer.metadata[MESH_KEY]
        old = {r.label: r.text for r in self.table.records}
        self.table.set_records([
            Conductivity(int(m), mesh.material_names.get(int(m), ""), old.get(int(m), "1"))
            for m in np.unique(mesh.material)])
        for name, box in self.axis_boxes.items():
            box.visible = name != "z" or mesh.ndim == 3
        self.show_combo.choices = ["x", "y", "z"][:mesh.ndim]

    def axes(self, ndim: int) -> list[str]:
        return [a for a, box in self.axis_boxes.items() if box.value and "xyz".index(a) < ndim]

    # -- run -------------------------------------------------------------------------------
    def run(self, *_):
        """Solve on the selected mesh in a worker; show k_eff and the field when done."""
        layer = self.mesh_combo.value
        if layer is None:
            notify_error("no mesh to simulate on: mesh a Labels layer first (mesh widget).")
            return None
        mesh = layer.metadata[MESH_KEY]
        try:
            conductivity = self.table.conductivity()
        except ValueError as exc:
            notify_error(f"{exc} Edit it in the table.")
            return None
        axes = self.axes(mesh.ndim)
        if not axes:
            notify_error("tick at least one axis to compute k_eff along.")
            return None
        order = ORDERS[self.order_combo.value]

        def steps():
            return simulate_steps(mesh, conductivity, order=order, axes=axes)

        return self.tasks.run(steps, title="Simulation",
                              on_result=lambda result: self._show_result(layer, result))

    # -- results (main thread) -------------------------------------------------------------
    def _show_result(self, mesh_layer, result: "SimulationResult") -> None:
        self.result = result
        self.summary.value = result.describe()
        self.show_combo.value = next(iter(result.k_eff))
        self.show_field(mesh_layer=mesh_layer)
        self.plot.redraw()
        self.export_button.enabled = True
        self.simulated.emit(result)

    def show_field(self, *_, mesh_layer=None) -> None:
        """Show the potential along the chosen axis on the boundary and interface faces."""
        result = self.result
        axis = self.show_combo.value
        if result is None or axis not in result.potential:
            return
        mesh = result.mesh
        faces, _ = shown_faces(mesh.cells, mesh.material)
        data = (mesh.points, faces, result.potential[axis])
        name = "potential"
        if self.field_layer is not None and self.field_layer in self.viewer.layers:
            self.field_layer.data = data
            self.field_layer.name = name
        else:
            translate = mesh_layer.translate if mesh_layer is not None else np.zeros(mesh.ndim)
            affine = mesh_layer.affine.affine_matrix if mesh_layer is not None else None
            self.field_layer = self.viewer.add_surface(
                data, name=name, colormap=COLORMAP, contrast_limits=(0.0, 1.0),
                translate=translate, affine=affine, shading="smooth" if mesh.ndim == 3 else "none",
                metadata={FIELD_KEY: axis})
        self.field_layer.metadata[FIELD_KEY] = axis

    def _draw_figure(self, figure: "Figure") -> None:
        """Colour bar of the potential, and k_eff per axis inside its bounds."""
        figure.clear()
        result = self.result
        if result is None:
            return
        import matplotlib as mpl

        bar_ax, k_ax = figure.subplots(2, 1, height_ratios=[1, 3])
        figure.colorbar(mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, 1), cmap=COLORMAP),
                        cax=bar_ax, orientation="horizontal")
        bar_ax.set_title("potential (0 on the min face, 1 on the max face)", fontsize=8)
        bar_ax.tick_params(labelsize=7)
        names = list(result.k_eff)
        y = np.arange(len(names))
        lows = np.array([result.bounds[a][0] for a in names])
        highs = np.array([result.bounds[a][1] for a in names])
        k_ax.hlines(y, lows, highs, color="0.6", lw=6, label="Reuss .. Voigt")
        k_ax.plot([result.k_eff[a] for a in names], y, "o", color="#d62728", label="k_eff")
        k_ax.set_yticks(y, names)
        k_ax.set_xscale("log" if highs.max() > 20 * max(lows.min(), 1e-300) else "linear")
        k_ax.set_xlabel("conductivity", fontsize=8)
        k_ax.tick_params(labelsize=7)
        k_ax.legend(fontsize=7, frameon=False)
        figure.set_layout_engine("constrained")

    # -- export ----------------------------------------------------------------------------
    def export_field(self, path):
        """Write the last result's mesh and fields (.vtu or .xdmf) in a worker."""
        if self.result is None:
            notify_error("simulate first; there is no field to export yet.")
            return None
        result = self.result

        def steps():
            yield 0, 1, f"writing {path}"
            written = write_field(result, path, force=True)
            yield 1, 1, "done"
            return written

        return self.tasks.run(steps, title="Field export", on_result=lambda written:
                              notify_info("field written to " + ", ".join(map(str, written))))

    def _on_export_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export field", "field.vtu",
                                              "VTK XML (*.vtu);;XDMF (*.xdmf)")
        if path:
            self.export_field(path)
