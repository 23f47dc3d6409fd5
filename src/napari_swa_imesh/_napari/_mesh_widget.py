"""Mesh widget: IMESH a Labels layer into a Surface coloured per element, with its quality.

The Surface shows the mesh's boundary and material interfaces, or, with the clip of
:mod:`._clip_panel` on, the surface of the whole elements on one side of a plane
(:class:`~napari_swa_imesh.mesh.MeshClipper`); either way the same layer is updated in place.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, FloatSpinBox, PushButton, SpinBox
from qtpy.QtCore import Qt, Signal
from qtpy.QtWidgets import QFileDialog, QLabel, QListWidget, QListWidgetItem, QWidget

from ..mesh import (
    ASPECT_LIMIT,
    MeshClipper,
    check_mesh,
    mesh_formats,
    mesh_labels,
    mesh_surface,
    write_mesh,
)
from ._clip_panel import ClipPanel
from ._dock import fit_dock, scroll_body, wrapped_label
from ._help import explain_terms
from ._layers import (
    MESH_KEY,
    default_color,
    is_layer,
    layer_picker,
    layer_spacing,
    mesh_translate,
    pick,
    placed_by_affine,
)
from ._mesh_bounds import _bound_line, _mesh_bound, bound_label, bound_range, quality_legend
from ._plots import ThemedFigure, dark_theme, theme_text_color
from ._tasks import TaskPanel, notify_error, notify_info

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    import napari

    from ..mesh import Mesh

__all__ = ["MeshWidget", "COLOR_BY_QUALITY", "COLOR_BY_MATERIAL", "CHECKS_KEY",
           "SURFACE_VALUES_KEY", "bound_range", "bound_label"]

COLOR_BY_QUALITY = "quality (radius-to-edge)"
COLOR_BY_MATERIAL = "material"
CHECKS_KEY = "swa_imesh_checks"
SURFACE_VALUES_KEY = "swa_imesh_surface_values"
METHODS = ("template", "delaunay")
_ELEMENT = {2: "triangles", 3: "tetrahedra"}


def text_overlay(viewer):
    """The viewer's canvas text overlay (``canvas.overlays.text`` from napari 0.9)."""
    canvas = getattr(viewer, "canvas", None)
    overlays = getattr(canvas, "overlays", None)
    return overlays["text"] if overlays is not None and "text" in overlays \
        else viewer.text_overlay


def _labels_present(data: np.ndarray) -> list[int]:
    """Sorted label values of `data`; a bincount (O(N), no sort) for non-negative ints."""
    if data.dtype.kind in "iu" and data.size and data.min() >= 0 and data.max() < 1 << 24:
        return np.flatnonzero(np.bincount(data.ravel())).tolist()
    return np.unique(data).tolist()


def _values(surface: dict) -> dict[str, np.ndarray]:
    """Per-vertex values of a surface in both colourings (the layer's metadata)."""
    return {"quality": surface["quality"], "material": surface["material"]}


class MeshWidget(QWidget):
    """Mesh a Labels layer; show the mesh, its quality histogram and checks; export it.

    Signals
    -------
    mesh_ready(object)
        A mesh Surface layer was created or updated.
    """

    mesh_ready = Signal(object)

    def __init__(self, napari_viewer: napari.viewer.Viewer, parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.mesh: Mesh | None = None
        self.checks: dict | None = None
        self.surface_layer = None
        self.labels_combo = layer_picker(self.viewer, "Labels", label="labels")
        self.method_combo = ComboBox(
            label="method", choices=METHODS,
            tooltip="template: look-up-table mesher, conforming with a quality bound; "
                    "delaunay: the reference's Qhull step, for comparison (not conforming "
                    "in 3-D).")
        self.exclude_list = QListWidget()
        self.exclude_list.setMaximumHeight(110)
        self.exclude_list.setToolTip("Checked materials are not meshed; their faces become "
                                     "the mesh boundary.")
        self.refine_spin = SpinBox(
            label="refine", value=0, min=0, max=4,
            tooltip="Elements sharing a facet with a material interface are 2^-K voxels "
                    "(template method); the interior coarsens as before.")
        self.max_size_spin = FloatSpinBox(
            label="max edge", value=0.0, min=0.0, max=1e9, step=1.0,
            tooltip="Longest element edge allowed, in the layer's units (0: no cap).")
        self.max_aspect_spin = FloatSpinBox(
            label="max aspect", value=ASPECT_LIMIT, min=1.0, max=4.0, step=0.05,
            tooltip="Anisotropic voxels are cut into the fewest cells whose sides differ by "
                    "at most this factor: 1.25 (default) keeps radius-to-edge <= 1.38 and "
                    "dihedral angles >= 29.5 deg; larger gives fewer elements and a looser "
                    "bound (swa-imesh bounds --dim 3 --spacing ... lists the choices).")
        self.subdivide_box = CheckBox(
            text="cut anisotropic voxels into near-cubic cells (quality bound)", value=True)
        self.checks_box = CheckBox(
            text="check the mesh (conforming, volumes, labels recovered)", value=True)
        self.color_combo = ComboBox(label="colour by",
                                    choices=[COLOR_BY_QUALITY, COLOR_BY_MATERIAL])
        self.edges_box = CheckBox(text="show element edges", value=True)
        self.mesh_button = PushButton(text="Mesh")
        self.export_button = PushButton(text="Export mesh...", enabled=False, tooltip=(
            "Write the mesh (" + ", ".join(f.suffix for f in mesh_formats()) + ")."))
        self.summary = wrapped_label()
        self.summary.native.setTextInteractionFlags(Qt.TextSelectableByMouse)
        self.plot = ThemedFigure(self.viewer, self._draw_histogram, min_height=180)
        self.tasks = TaskPanel()
        self.full_surface: dict | None = None
        self.clip = ClipPanel(self.refresh_surface)

        layout = scroll_body(self)
        layout.addWidget(Container(widgets=[self.labels_combo, self.method_combo,
                                            self.refine_spin, self.max_size_spin,
                                            self.subdivide_box,
                                            self.max_aspect_spin]).native)
        layout.addWidget(QLabel("exclude"))
        layout.addWidget(self.exclude_list)
        layout.addWidget(Container(widgets=[self.checks_box, self.color_combo, self.edges_box,
                                            self.mesh_button]).native)
        layout.addWidget(self.tasks)
        layout.addWidget(self.summary.native)
        layout.addWidget(self.plot, 1)
        self.clip_box = self.clip.widget()
        layout.addWidget(self.clip_box)
        layout.addWidget(self.export_button.native)
        fit_dock(self)
        self.labels_combo.changed.connect(self._refresh_materials)
        self.color_combo.changed.connect(self.apply_colors)
        self.edges_box.changed.connect(self.apply_colors)
        self.mesh_button.changed.connect(self.run_mesh)
        self.export_button.changed.connect(self._on_export_clicked)
        self._refresh_materials()
        explain_terms(self)

    @property
    def figure(self) -> Figure:
        return self.plot.figure

    # -- inputs ----------------------------------------------------------------------------
    def select_labels(self, layer) -> None:
        """Mesh this Labels layer next (the workflow passes the classification)."""
        pick(self.labels_combo, layer)
        self._refresh_materials()

    def _refresh_materials(self, *_) -> None:
        layer = self.labels_combo.value
        self.exclude_list.clear()
        if layer is None:
            return
        names = {int(k): str(v) for k, v in layer.metadata.get("material_names", {}).items()}
        for label in _labels_present(np.asarray(layer.data)):
            text = f"{label}  {names.get(label, 'background' if label == 0 else '')}".rstrip()
            item = QListWidgetItem(text)
            item.setData(Qt.UserRole, int(label))
            item.setFlags(item.flags() | Qt.ItemIsUserCheckable)
            item.setCheckState(Qt.Checked if label == 0 else Qt.Unchecked)
            self.exclude_list.addItem(item)

    def excluded(self) -> list[int]:
        """Labels checked for exclusion."""
        return [self.exclude_list.item(i).data(Qt.UserRole)
                for i in range(self.exclude_list.count())
                if self.exclude_list.item(i).checkState() == Qt.Checked]

    def set_excluded(self, labels) -> None:
        wanted = {int(v) for v in labels}
        for i in range(self.exclude_list.count()):
            item = self.exclude_list.item(i)
            item.setCheckState(Qt.Checked if item.data(Qt.UserRole) in wanted else Qt.Unchecked)

    # -- run -------------------------------------------------------------------------------
    def run_mesh(self):
        """Mesh the selected Labels layer in a worker; show it when done."""
        layer = self.labels_combo.value
        if layer is None:
            notify_error("no Labels layer to mesh: classify an image first (classify widget) "
                         "or open a label image, and pick it in the mesh widget.")
            return None
        if layer.ndim not in (2, 3):
            notify_error(f"Labels layer {layer.name!r} is {layer.ndim}-D; IMESH meshes 2-D "
                         "and 3-D label images, so pick one of those.")
            return None
        data = np.asarray(layer.data)
        spacing, exclude = layer_spacing(layer), self.excluded()
        method, run_checks = self.method_combo.value, self.checks_box.value
        names = {int(k): str(v) for k, v in layer.metadata.get("material_names", {}).items()}
        # read from NIfTI (and its scale untouched): files get the file's world frame
        place = placed_by_affine(layer)
        resolution = {}
        if method == "template":
            resolution = {"refine": int(self.refine_spin.value),
                          "subdivide": bool(self.subdivide_box.value),
                          "max_aspect": (float(self.max_aspect_spin.value)
                                         if self.subdivide_box.value else None),
                          "max_size": float(self.max_size_spin.value) or None}
        elif self.refine_spin.value or self.max_size_spin.value:
            notify_error("refine and max edge apply to the template method; set them to 0 "
                         "or pick the template method.")
            return None
        else:
            resolution = {"subdivide": False}

        def steps():
            yield 0, 3, f"{method} mesh of the balanced 2^d-tree"
            # mesh_labels runs the library's plan (plan_mesh), as the command line does
            mesh = mesh_labels(data, method=method, exclude=exclude, material_names=names,
                               **resolution,
                               **({"affine": place} if place is not None else
                                  {"spacing": spacing}))
            checks = None
            if run_checks:
                yield 1, 3, "checking the mesh (conforming, volumes, labels recovered)"
                checks = check_mesh(mesh, data, exclude=exclude)
            yield 2, 3, "faces to draw"
            surface = mesh_surface(mesh)
            clipper = MeshClipper(mesh, shown=(surface["faces"], surface["owners"]))
            clipper.kept(0, 0.0)         # the element extents on the first axis, here
            bound_range(mesh.ndim)       # cached here, not computed in the main thread
            _mesh_bound(mesh)
            yield 3, 3, "done"
            return mesh, checks, surface, clipper

        return self.tasks.run(steps, title="IMESH meshing",
                              on_result=lambda out: self._show_mesh(layer, *out))

    # -- results (main thread) ---------------------------------------------------------------
    def _show_mesh(self, labels, mesh: Mesh, checks, full: dict, clipper) -> None:
        self.mesh, self.checks, self.full_surface = mesh, checks, full
        self.clip.set_clipper(clipper)
        surface = self._shown_surface()
        data = (surface["vertices"], surface["triangles"], surface["quality"])
        metadata = {MESH_KEY: mesh, CHECKS_KEY: checks, SURFACE_VALUES_KEY: _values(surface)}
        name = f"{labels.name} mesh"
        translate = mesh_translate(labels)
        existing = self.viewer.layers[name] if name in self.viewer.layers else None
        if existing is not None and is_layer(existing, "Surface") and \
                existing.ndim == mesh.ndim:
            existing.vertex_colors = None
            existing.data = data
            existing.translate = translate
            existing.affine = labels.affine.affine_matrix
            existing.metadata.update(metadata)
            layer = existing
        else:
            # flat shading gives 3-D faces depth; in 2-D it would only darken the colours
            layer = self.viewer.add_surface(data, name=name, translate=translate,
                                            affine=labels.affine.affine_matrix,
                                            metadata=metadata,
                                            shading="flat" if mesh.ndim == 3 else "none")
        self.surface_layer = layer
        self.apply_colors()
        self._show_summary(mesh, checks, full["n_faces"])
        self.clip.show_counts(surface)
        self.plot.redraw()
        self.export_button.enabled = True
        self.mesh_ready.emit(layer)

    def _shown_surface(self) -> dict:
        """The whole mesh's surface, or the clipped one when the clip is on."""
        if self.clip.active:
            axis, position, keep = self.clip.settings()
            return self.clip.clipper.surface(axis, position, keep=keep)
        return self.full_surface

    def refresh_surface(self) -> None:
        """Draw the clip's current surface (or the whole mesh's) in the same layer."""
        layer = self.surface_layer
        if layer is None or self.full_surface is None or layer not in self.viewer.layers:
            return
        surface = self._shown_surface()
        layer.metadata[SURFACE_VALUES_KEY] = _values(surface)
        # each setter of a Surface redraws it (normals and all): set as few as possible
        if layer.vertex_colors is not None:
            layer.vertex_colors = None   # sized for the old vertices
        layer.data = (surface["vertices"], surface["triangles"], surface["quality"])
        self.apply_colors()
        self.clip.show_counts(surface)

    def apply_colors(self, *_) -> None:
        """Colour the mesh Surface by element quality or by material."""
        layer = self.surface_layer
        if layer is None or SURFACE_VALUES_KEY not in layer.metadata:
            return
        values = layer.metadata[SURFACE_VALUES_KEY]
        mesh = layer.metadata[MESH_KEY]
        layer.wireframe.visible = self.edges_box.value
        layer.wireframe.color = "black"
        if self.color_combo.value == COLOR_BY_MATERIAL and len(values["material"]):
            from napari.utils.colormaps.standardize_color import transform_color

            materials = np.unique(mesh.material)
            table = np.stack([transform_color(default_color(m))[0] for m in materials])
            layer.vertex_colors = table[np.searchsorted(materials, values["material"])]
            self._show_legend(None)
        else:
            # limits of the whole mesh, so colours keep their meaning as the clip moves
            lo, hi = _mesh_bound(mesh)
            worst = float(np.max(mesh.quality)) if mesh.n_cells else hi
            if layer.vertex_colors is not None:
                layer.vertex_colors = None
            if layer.vertex_values is not values["quality"]:
                layer.vertex_values = values["quality"]
            layer.colormap = "turbo"
            layer.contrast_limits = [lo, max(hi, worst) + 1e-9]
            self._show_legend(quality_legend(mesh, lo, hi, worst))

    def _show_legend(self, text: str | None) -> None:
        """The colour bar of the quality colouring on the canvas, and its bound as text
        (None: hide both, e.g. when coloured by material)."""
        layer = self.surface_layer
        colorbar = getattr(layer, "colorbar", None)     # napari >= 0.6 draws one per layer
        if colorbar is not None:
            colorbar.visible = text is not None
        overlay = text_overlay(self.viewer)
        if text is not None:
            overlay.text, overlay.visible = text, True
            overlay.position, overlay.font_size = "bottom_left", 10
            self._legend_text, self._legend_layer = text, layer
            # the text speaks for this layer only: hidden or removed, it goes too
            layer.events.visible.connect(self._sync_legend)
            self.viewer.layers.events.removed.connect(self._sync_legend)
        elif overlay.text == getattr(self, "_legend_text", None):   # ours: take it away
            overlay.text, overlay.visible = "", False
            self._legend_layer = None

    def _sync_legend(self, event=None) -> None:
        """Show the quality text while its mesh layer is in the viewer and visible."""
        layer, overlay = getattr(self, "_legend_layer", None), text_overlay(self.viewer)
        if layer is None or overlay.text != getattr(self, "_legend_text", None):
            return
        overlay.visible = layer in self.viewer.layers and bool(layer.visible)

    def _show_summary(self, mesh: Mesh, checks, n_faces: int) -> None:
        info = mesh.info
        element = _ELEMENT[mesh.ndim]
        materials, counts = np.unique(mesh.material, return_counts=True)
        per_material = ", ".join(
            f"{mesh.material_names.get(int(m), int(m))}: {c}" for m, c in zip(materials, counts))
        lo, hi = info.get("angle_range", (float("nan"), float("nan")))
        angle = "angles" if mesh.ndim == 2 else "dihedral angles"
        lines = [f"{len(mesh.points)} vertices, {mesh.n_cells} {element} ({per_material})",
                 f"worst radius-to-edge ratio {float(mesh.quality.max()):.3f}; "
                 f"{angle} {lo:.1f} to {hi:.1f} deg",
                 _bound_line(mesh)]
        if checks is None:
            lines.append("checks not run")
        elif checks.get("all_passed"):
            lines.append("checks: all passed (conforming, positive volumes, every element in "
                         "one leaf, labels recovered)")
        else:
            failed = [k for k, v in checks.items() if v is False]
            lines.append(f"checks FAILED: {', '.join(failed)}")
        if mesh.ndim == 3:
            lines.append(f"shown: {n_faces} boundary and interface faces (3-D view: "
                         "View > Toggle Ndisplay)")
        self.summary.value = "\n".join(lines)

    def _draw_histogram(self, figure: Figure) -> None:
        """Element quality histogram; the IMESH bound range (:func:`bound_range`) shaded."""
        figure.clear()
        mesh = self.mesh
        if mesh is None:
            return
        ax = figure.add_subplot(1, 1, 1)
        q = mesh.quality[np.isfinite(mesh.quality)]
        lo, hi = _mesh_bound(mesh)
        band = ax.axvspan(lo, hi, color="#2ca02c", alpha=0.18, lw=0, label=bound_label(mesh))
        band.set_gid("bound")
        # the range always spans the bound, so a mesh of one element shape still bins
        span = (min(lo, float(q.min(initial=lo))), max(hi, float(q.max(initial=hi))))
        ax.hist(q, bins=40, range=span, color="#6fb1ff" if dark_theme(self.viewer) else "#1f77b4")
        ax.set_yscale("log")
        ax.set_xlabel("radius-to-edge ratio (circumradius / shortest edge)", fontsize=8)
        ax.set_ylabel("elements", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, frameon=False, labelcolor=theme_text_color(self.viewer))

    # -- export ----------------------------------------------------------------------------
    def export_mesh(self, path):
        """Write the current mesh in the format `path`'s suffix names, in a worker."""
        if self.mesh is None:
            notify_error("mesh a Labels layer first; there is no mesh to export yet.")
            return None
        mesh = self.mesh

        def steps():
            yield 0, 1, f"writing {path}"
            written = write_mesh(mesh, path, force=True)
            yield 1, 1, "done"
            return written

        return self.tasks.run(steps, title="Mesh export", on_result=lambda written:
                              notify_info("mesh written to " + ", ".join(map(str, written))))

    def _on_export_clicked(self) -> None:
        filters = ";;".join(f"{f.description} (*{f.suffix})" for f in mesh_formats())
        path, _ = QFileDialog.getSaveFileName(self, "Export mesh", "mesh.vtu", filters)
        if path:
            self.export_mesh(path)
