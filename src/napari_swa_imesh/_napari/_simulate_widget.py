"""Simulate widget: steady diffusion on an IMESH mesh layer, k_eff per axis, the field shown.

Thin: the conductivity table is a view of a list of records, the computation is
:func:`napari_swa_imesh.simulate.simulate_steps` in the task panel's worker, and the result
is drawn as a Surface coloured by the potential (on the mesh's boundary and interface
faces, or on the surface of the whole elements on one side of a clipping plane, as the Mesh
tab's clip: :class:`~napari_swa_imesh.mesh.MeshClipper`), with a figure holding the colour
bar and each k_eff inside its Reuss-Voigt interval and its certified interval (the summary
text gives both bounds and the gap); the periodic tensor is a small table
and the signatures + k_eff report a box of its own (:mod:`._report_panel`).

The tab simulates the Mesh tab's mesh as it is. Interface refinement and periodic faces
are made by the mesher, so a refine level other than the mesh's, or the periodic protocol
on a mesh without periodic faces, meshes the labels again for the run with every other
setting of the mesh (:func:`napari_swa_imesh.simulate._remesh.remesh`, which checks the
labels are the mesh's image); a line under the controls says which mesh the run will use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, PushButton, SpinBox
from qtpy.QtCore import Qt, Signal
from qtpy.QtWidgets import QFileDialog, QLabel, QTableWidget, QWidget

from ..mesh import MeshClipper, shown_faces
from ..simulate import P1_GROWTH, mesh_refine, needs_remesh, remesh, simulate_steps, write_field
from ._clip_panel import ClipPanel
from ._conductivity_table import Conductivity, ConductivityTable, parse_conductivity
from ._dock import fit_dock, scroll_body, side_by_side, wrapped_label
from ._growth_panel import GrowthPanel
from ._help import explain_terms, set_tooltip
from ._layers import MESH_KEY, layer_picker, pick
from ._plots import ThemedFigure
from ._report_panel import ReportPanel, classification_signatures, fill_table
from ._stochastic_panel import StochasticPanel, source_of
from ._tasks import TaskPanel, notify_error, notify_info

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    import napari

    from ..simulate import SimulationResult

__all__ = ["SimulateWidget", "Conductivity", "ConductivityTable", "parse_conductivity",
           "FIELD_KEY", "PROTOCOLS"]

FIELD_KEY = "swa_imesh_field"
#: elements -> (order, adapt): P1 on the mesh as shown, or adapted within P1_GROWTH x its vertices
ORDERS = {"auto: P2, refined once where the flux jumps": ("auto", "auto"),
          "P1 (linear)": (1, 0),
          "P1, refined twice where the flux jumps (at most 3x the vertices)": (1, "auto"),
          "P2 (quadratic, more accurate)": (2, "auto")}
PROTOCOLS = [("mixed: k_eff per axis (potential 0 and 1 on two faces)", "mixed"),
             ("periodic: the full tensor (unit mean gradient)", "periodic")]
COLORMAP = "turbo"


class SimulateWidget(QWidget):
    """Effective conductivity of the image box from a mesh layer; field on the surface.

    Signals
    -------
    simulated(object)
        The :class:`SimulationResult` of a finished run.
    """

    simulated = Signal(object)

    def __init__(self, napari_viewer: napari.viewer.Viewer, parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.result: SimulationResult | None = None
        self._result_layer = None                   # the mesh layer `result` was run on
        self.field_layer = None
        self._faces: np.ndarray | None = None       # boundary and interface faces
        self.mesh_combo = layer_picker(self.viewer, "Surface", label="mesh",
                                       accept=lambda layer: MESH_KEY in layer.metadata)
        self.labels_combo = layer_picker(
            self.viewer, "Labels", label="labels", none_text="(none)",
            tooltip="The label image the mesh was made from: meshed again when the refine "
                    "level or the periodic protocol needs another mesh; its classification "
                    "gives the signatures of the report.")
        self.table = ConductivityTable()
        self.order_combo = ComboBox(label="elements", choices=list(ORDERS))
        self.protocol_combo = ComboBox(label="protocol", choices=PROTOCOLS)
        self.refine_spin = SpinBox(
            label="refine", value=0, min=0, max=4,
            tooltip="Elements at material interfaces are 2^-K voxels. Another level than "
                    "the mesh's meshes the labels again for the run.")
        self.mesh_note = wrapped_label()
        self.axis_boxes = {a: CheckBox(text=a, value=True) for a in "xyz"}
        self.show_combo = ComboBox(label="show potential of", choices=["x", "y", "z"])
        self.run_button = PushButton(text="Simulate")
        self.export_button = PushButton(text="Export field...", enabled=False,
                                        tooltip="Write the mesh with potential and flux per "
                                                "axis (.vtu or .xdmf, for ParaView).")
        self.summary = wrapped_label()
        self.summary.native.setTextInteractionFlags(Qt.TextSelectableByMouse)
        self.tensor_table = QTableWidget(0, 0)
        self.tensor_table.setEditTriggers(QTableWidget.NoEditTriggers)
        self.tensor_table.setMaximumHeight(110)
        self.tensor_table.setVisible(False)
        self.plot = ThemedFigure(self.viewer, self._draw_figure, min_height=160)
        self.tasks = TaskPanel()
        self.clip = ClipPanel(self.show_field)
        self.clip.status.value = "simulate to clip the field"
        self.report = ReportPanel()
        self.stochastic = StochasticPanel(self.viewer, lambda: source_of(
            self.mesh_combo.value, self.labels_combo.value))

        layout = scroll_body(self)
        layout.addWidget(Container(widgets=[self.mesh_combo, self.labels_combo]).native)
        layout.addWidget(QLabel("conductivity per material"))
        layout.addWidget(self.table)
        layout.addWidget(Container(widgets=[self.order_combo, self.protocol_combo,
                                            self.refine_spin]).native)
        layout.addWidget(self.mesh_note.native)
        layout.addWidget(QLabel("k_eff along (x = column, y = row, z = plane)"))
        layout.addWidget(side_by_side(*self.axis_boxes.values()))
        layout.addWidget(self.run_button.native)
        layout.addWidget(self.tasks)
        layout.addWidget(self.summary.native)      # k_eff next to the button
        layout.addWidget(Container(widgets=[self.show_combo]).native)
        layout.addWidget(self.tensor_table)
        layout.addWidget(self.plot, 1)
        self.clip_box = self.clip.widget()
        layout.addWidget(self.clip_box)
        self.report_box = self.report.widget()
        layout.addWidget(self.report_box)
        self.stochastic_box = self.stochastic.widget()
        layout.addWidget(self.stochastic_box)
        layout.addWidget(self.export_button.native)
        self.growth = GrowthPanel(self)           # reaction-diffusion (issue 28)
        layout.addWidget(self.growth.fold)
        fit_dock(self)
        self.mesh_combo.changed.connect(self._on_mesh_changed)
        self.labels_combo.changed.connect(self._on_labels_changed)
        for control in (self.protocol_combo, self.refine_spin, self.order_combo):
            control.changed.connect(self._update_note)
        self.show_combo.changed.connect(self._on_show_changed)
        self.run_button.changed.connect(self.run)
        self.export_button.changed.connect(self._on_export_clicked)
        self._on_mesh_changed()
        explain_terms(self)

    @property
    def figure(self) -> Figure:
        return self.plot.figure

    # -- inputs ----------------------------------------------------------------------------
    def select_mesh(self, layer, labels=None) -> None:
        """Simulate on this mesh layer next (the workflow passes the new mesh and the labels
        it was made from; without them, the Labels layer named as the mesh's source)."""
        pick(self.mesh_combo, layer)
        if labels is None and layer is not None and layer.name.endswith(" mesh"):
            source = layer.name[:-len(" mesh")]
            layers = self.viewer.layers
            labels = layers[source] if source in layers else None
        if labels is not None:
            pick(self.labels_combo, labels)
        self._on_mesh_changed()

    def _on_mesh_changed(self, *_) -> None:
        layer = self.mesh_combo.value
        if self.result is not None and layer is not self._result_layer:
            # the last run belongs to another mesh (deleted or not picked): its report must
            # not meet the signatures of the labels picked next
            self.result, self._result_layer = None, None
            self.report.set_result(None)
            self.export_button.enabled = False
        if layer is None:
            self.table.set_records([])
            self._update_note()
            return
        mesh = layer.metadata[MESH_KEY]
        old = {r.label: r.text for r in self.table.records}
        self.table.set_records([
            Conductivity(int(m), mesh.material_names.get(int(m), ""), old.get(int(m), "1"))
            for m in np.unique(mesh.material)])
        for name, box in self.axis_boxes.items():
            box.visible = name != "z" or mesh.ndim == 3
        self.show_combo.choices = ["x", "y", "z"][:mesh.ndim]
        with self.refine_spin.changed.blocked():
            self.refine_spin.value = mesh_refine(mesh)    # by default, the mesh as it is
        self._update_note()

    def _on_labels_changed(self, *_) -> None:
        layer = self.labels_combo.value
        rows = classification_signatures(layer)
        self.stochastic.follow_labels(rows, layer)
        if rows:
            self.report.set_signatures(rows, f"classification of {layer.name!r}")
        elif self.report.source.startswith("classification of"):
            self.report.set_signatures(None, "")        # another image's: not these labels'
        self._update_note()

    def axes(self, ndim: int) -> list[str]:
        return [a for a, box in self.axis_boxes.items() if box.value and "xyz".index(a) < ndim]

    def _remeshing(self) -> bool:
        layer = self.mesh_combo.value
        return layer is not None and needs_remesh(
            layer.metadata[MESH_KEY], refine=int(self.refine_spin.value),
            periodic=self.protocol_combo.value == "periodic")

    def _adapt_note(self) -> str:
        order, adapt = ORDERS[self.order_combo.value]
        if adapt == 0 or order == 2 or self.labels_combo.value is None:
            return ""
        if order == 1:
            return f", refined twice where the flux jumps, within {P1_GROWTH:g}x the vertices"
        return ", refined once more where the flux jumps (auto) if P2 fits the budget"

    def _update_note(self, *_) -> None:
        """Say which mesh the run will use: the one shown, or the labels meshed again."""
        layer = self.mesh_combo.value
        if layer is None:
            self.mesh_note.value = "mesh a Labels layer first (Mesh tab)"
            return
        mesh = layer.metadata[MESH_KEY]
        shown = (f"refine {mesh_refine(mesh)}"
                 + (", periodic faces" if mesh.recipe is not None and mesh.recipe.periodic
                    else ""))
        if not self._remeshing():
            self.mesh_note.value = f"the run uses the mesh as shown ({mesh.n_cells} " \
                                   f"elements, {shown})" + self._adapt_note()
            return
        wanted = f"refine {int(self.refine_spin.value)}" + (
            " with periodic faces" if self.protocol_combo.value == "periodic" else "")
        labels = self.labels_combo.value
        self.mesh_note.value = (
            f"{wanted} needs another mesh than the one shown ({shown}): the run meshes "
            f"{labels.name!r} again with the mesh's other settings" if labels is not None
            else f"{wanted} needs another mesh than the one shown ({shown}): pick the labels "
                 "it was made from, or set refine back to the mesh's")

    # -- run -------------------------------------------------------------------------------
    def run(self, *_):
        """Solve on the selected mesh (or its labels meshed again) in a worker; show k_eff
        and the field when done."""
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
        order, adapt = ORDERS[self.order_combo.value]
        protocol, refine = self.protocol_combo.value, int(self.refine_spin.value)
        labels = None
        if self._remeshing():
            if self.labels_combo.value is None:
                notify_error(f"refine {refine}" + (" and periodic faces" if protocol ==
                                                    "periodic" else "") +
                             " need a new mesh: pick the labels the mesh was made from, or "
                             "set refine to the mesh's and use the mixed protocol.")
                return None
            labels = np.asarray(self.labels_combo.value.data)
        source = labels
        picked = self.labels_combo.value
        if source is None and picked is not None and tuple(picked.data.shape) == tuple(mesh.shape):
            source = np.asarray(picked.data)   # lets the default adapt the mesh to the field

        def steps():
            run_mesh = mesh
            if labels is not None:
                yield 0, 1, f"meshing the labels again (refine {refine}, {protocol})"
                run_mesh = remesh(mesh, labels, refine=refine, periodic=protocol == "periodic")
            result = yield from simulate_steps(run_mesh, conductivity, order=order, axes=axes,
                                               protocol=protocol, labels=source,
                                               adapt=adapt if source is not None else 0)
            shown = shown_faces(result.mesh.cells, result.mesh.material)
            clipper = MeshClipper(result.mesh, shown=shown)
            return result, shown[0], clipper

        return self.tasks.run(steps, title="Simulation",
                              on_result=lambda out: self._show_result(layer, conductivity,
                                                                      *out))

    # -- results (main thread) -------------------------------------------------------------
    def _show_result(self, mesh_layer, conductivity, result: SimulationResult,
                     faces: np.ndarray, clipper: MeshClipper) -> None:
        self.result, self._faces, self._result_layer = result, faces, mesh_layer
        self.summary.value = _brief(result)
        set_tooltip(self.summary.native, result.describe())   # the whole account
        self.clip.set_clipper(clipper)
        with self.show_combo.changed.blocked():
            self.show_combo.value = next(iter(result.k_eff))
        self.show_field(mesh_layer=mesh_layer)
        self._show_tensor(result)
        self.plot.redraw()
        self.export_button.enabled = True
        self.report.set_result(result, conductivity)
        self.simulated.emit(result)

    def _show_tensor(self, result: SimulationResult) -> None:
        tensor = result.tensor
        self.tensor_table.setVisible(tensor is not None)
        if tensor is None:
            return
        axes = ["x", "y", "z"][:len(tensor)]
        rows = [["K", *axes]] + [[a] + ["" if np.isnan(v) else f"{v:.6g}" for v in row]
                                 for a, row in zip(axes, tensor)]
        fill_table(self.tensor_table, rows, row_header=True)

    def field_limits(self) -> tuple[float, float]:
        """Colour range of the shown potential: its extent over the whole mesh (0 to 1 for
        the mixed protocol), so colours keep their meaning as the clip moves."""
        values = self.result.potential[self.show_combo.value]
        lo, hi = float(values.min()), float(values.max())
        return lo, max(hi, lo + 1e-12)

    def _on_show_changed(self, *_) -> None:
        self.show_field()
        self.plot.redraw()                   # the colour bar's range is the axis's

    def show_field(self, *_, mesh_layer=None) -> None:
        """Show the potential along the chosen axis on the boundary and interface faces, or
        on the surface of the elements the clip keeps."""
        result = self.result
        axis = self.show_combo.value
        if result is None or axis not in result.potential:
            return
        mesh = result.mesh
        if self.clip.active:
            normal, position, keep = self.clip.settings()
            kept, faces, _ = self.clip.clipper.faces(normal, position, keep=keep)
            self.clip.show_counts({"n_kept": int(np.count_nonzero(kept)),
                                   "n_faces": len(faces)})
        else:
            faces = self._faces
            self.clip.show_counts(None)
        data = (mesh.points, faces, result.potential[axis])
        limits = self.field_limits()
        if self.field_layer is not None and self.field_layer in self.viewer.layers:
            self.field_layer.data = data
            self.field_layer.contrast_limits = limits
        else:
            translate = mesh_layer.translate if mesh_layer is not None else np.zeros(mesh.ndim)
            affine = mesh_layer.affine.affine_matrix if mesh_layer is not None else None
            # unlit: every colour reads against the colour bar, faces turned away included
            self.field_layer = self.viewer.add_surface(
                data, name="potential", colormap=COLORMAP, contrast_limits=limits,
                translate=translate, affine=affine, shading="none",
                metadata={FIELD_KEY: axis})
        self.field_layer.metadata[FIELD_KEY] = axis

    def _draw_figure(self, figure: Figure) -> None:
        """Colour bar of the potential, and k_eff per axis inside its bounds."""
        figure.clear()
        result = self.result
        if result is None:
            return
        import matplotlib as mpl

        bar_ax, k_ax = figure.subplots(2, 1, height_ratios=[1, 3])
        lo, hi = self.field_limits()
        figure.colorbar(mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(lo, hi),
                                              cmap=COLORMAP),
                        cax=bar_ax, orientation="horizontal")
        axis = self.show_combo.value
        bar_ax.set_title(f"potential {axis}: 0 on the {axis}min face, 1 on the {axis}max face"
                         if result.protocol == "mixed" else
                         f"potential {axis}: {axis} + periodic fluctuation", fontsize=8)
        bar_ax.tick_params(labelsize=7)
        names = list(result.k_eff)
        y = np.arange(len(names))
        lows = np.array([result.bounds[a][0] for a in names])
        highs = np.array([result.bounds[a][1] for a in names])
        k_ax.hlines(y, lows, highs, color="0.6", lw=6, label="Reuss .. Voigt")
        if result.interval:               # the certified interval (dual .. primal)
            k_ax.hlines([names.index(a) for a in result.interval],
                        [lo for lo, _ in result.interval.values()],
                        [hi for _, hi in result.interval.values()], color="#1f77b4", lw=3,
                        label="certified")
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


def _brief(result: SimulationResult) -> str:
    """The tab's short account: k_eff per axis with its certified interval, and any
    warning (Reuss-Voigt is drawn in the figure; the whole text is the tooltip)."""
    lines = [f"P{result.order} on {result.mesh.n_cells} elements, {result.dofs} unknowns"
             + (f" ({result.choice})" if result.choice else "")]
    for axis, k in result.k_eff.items():
        line = f"k_eff {axis} = {k:.6g}"
        if axis in result.interval:
            lo, hi = result.interval[axis]
            line += f"  (certified {lo:.5g} .. {hi:.5g}, gap {100 * result.gap[axis]:.2g} %)"
        lines.append(line)
    return "\n".join(lines + [f"warning: {w}" for w in result.warnings])
