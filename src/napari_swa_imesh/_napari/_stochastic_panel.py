"""The stochastic box of the Simulate tab: k_eff of random fields drawn from the signatures.

Only the controls live here; the computation is
:func:`napari_swa_imesh.simulate.stochastic_steps` (plain Python, tested without Qt) in the
box's own task panel (progress and Cancel: the run stops after the block of samples that
is solving). The signatures are the classification's of the picked labels (the Classify
tab keeps them with the Labels layer) or a CSV file; the labels are meshed for the run
with elements of at most half the tile size (the Mesh tab's coarse leaves would average
the field away), else the mesh layer is used as it is. The histogram is drawn with the
napari theme (:class:`._plots.ThemedFigure`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import Container, FloatSpinBox, LineEdit, SpinBox

from ..simulate import signature_tile_size, stochastic_steps
from ._dock import Fold, button, side_by_side, wrapped_label
from ._layers import MESH_KEY
from ._plots import ThemedFigure
from ._signatures_input import SignaturesInput
from ._tasks import TaskPanel, notify_error

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    import napari

    from ..simulate import StochasticResult

__all__ = ["StochasticPanel", "source_of"]

DEFAULT_MAP = "log-linear:0,1"


def source_of(mesh_layer, labels_layer) -> tuple:
    """``(mesh, labels)`` for a run: the layer's mesh (or None) and the labels' array when
    they are the mesh's image (same shape), else None."""
    mesh = None if mesh_layer is None else mesh_layer.metadata[MESH_KEY]
    labels = None if labels_layer is None else np.asarray(labels_layer.data)
    if labels is not None and mesh is not None and tuple(labels.shape) != tuple(mesh.shape):
        labels = None
    return mesh, labels


class StochasticPanel(SignaturesInput):
    """Signatures source, N, map, tile size and seed; the run, its summary and histogram.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
    source : callable
        ``source() -> (mesh, labels)``: the Simulate tab's mesh (or None) and the picked
        label array (or None).
    """

    def __init__(self, viewer: napari.viewer.Viewer,
                 source: Callable[[], tuple]):
        self._source = source
        self.signatures: list[dict] | None = None
        self.source_name = ""
        self.result: StochasticResult | None = None
        self.source_label = wrapped_label()
        self.load_button = button("Load signatures CSV...", self._on_load_clicked,
                                  tooltip="swa-imesh segment --signatures, or the Classify "
                                          "tab's export: mean_mean and mean_std per material.")
        self.samples_spin = SpinBox(label="samples", value=50, min=2, max=100_000,
                                    tooltip="Realisations of the fields to solve.")
        self.map_edit = LineEdit(
            label="map", value=DEFAULT_MAP,
            tooltip="log-linear:A,B means log k = A + B * intensity: a Gaussian intensity "
                    "field gives a log-normal k.")
        self.tile_spin = FloatSpinBox(
            label="tile size", value=0.0, min=0.0, max=1e6, step=1.0,
            tooltip="The RES tile side in voxels, the fields' correlation length; 0 takes "
                    "2^scale from the signatures.")
        self.seed_spin = SpinBox(label="seed", value=0, min=0, max=2**31 - 1,
                                 tooltip="The same seed gives the same samples.")
        self.run_button = button("Run stochastic k_eff", self.run)
        self.tasks = TaskPanel()
        self.summary = wrapped_label()
        self.plot = ThemedFigure(viewer, self._draw_figure, min_height=140)
        self._show_source()

    def widget(self) -> Fold:
        """The box in a section that folds away (folded to start with)."""
        controls = Container(widgets=[self.samples_spin, self.map_edit, self.tile_spin,
                                      self.seed_spin])
        return Fold("stochastic k_eff from the signatures", [
            self.source_label, side_by_side(self.load_button), controls.native,
            self.run_button.native, self.tasks, self.summary, self.plot])

    # -- inputs ----------------------------------------------------------------------------
    def set_signatures(self, rows: list[dict] | None, source: str) -> None:
        """Draw the fields from these signatures (None: none) from now on."""
        self.signatures, self.source_name = rows, source if rows else ""
        self._show_source()

    def follow_labels(self, rows: list[dict] | None, layer) -> None:
        """The picked labels' classification signatures, if any; another image's
        classification is dropped (a loaded CSV stays)."""
        if rows:
            self.set_signatures(rows, f"classification of {layer.name!r}")
        elif self.source_name.startswith("classification of"):
            self.set_signatures(None, "")

    def _show_source(self) -> None:
        self.source_label.value = (
            f"signatures: {self.source_name} ({len(self.signatures)} materials)"
            if self.signatures else
            "no signatures: classify the labels (Classify tab) or load a CSV")

    # -- run -------------------------------------------------------------------------------
    def run(self, *_):
        """Check the inputs, then solve the samples in the task panel's worker."""
        mesh, labels = self._source()
        if mesh is None and labels is None:
            notify_error("no mesh to simulate on: mesh a Labels layer first (Mesh tab).")
            return None
        if not self.signatures:
            notify_error("no signatures: classify the labels (Classify tab) or load a "
                         "signatures CSV first.")
            return None
        try:
            tile = float(self.tile_spin.value) or signature_tile_size(self.signatures)
        except ValueError as exc:
            notify_error(str(exc))
            return None
        if not tile:
            notify_error("the signatures have no scale column: give the tile size (the "
                         "RES tile side in voxels).")
            return None
        spacing = np.asarray(mesh.spacing if mesh is not None and mesh.spacing else
                             (1.0,) * (mesh.ndim if mesh is not None else labels.ndim))
        run = {"samples": int(self.samples_spin.value), "correlation": tile * spacing,
               "property_map": str(self.map_edit.value).strip(),
               "seed": int(self.seed_spin.value)}
        if labels is not None:
            exclude = mesh.recipe.exclude if mesh is not None and mesh.recipe else ()
            run.update(spacing=tuple(spacing), exclude=tuple(exclude))
        names = dict(mesh.material_names) if mesh is not None else {}
        rows = [dict(r) for r in self.signatures]
        data = labels if labels is not None else mesh

        def steps():
            return (yield from stochastic_steps(data, rows, material_names=names, **run))

        worker = self.tasks.run(steps, title="Stochastic k_eff", on_result=self._show_result)
        if worker is not None:          # a run that fails must not leave the last one shown
            self._show_result(None)
        return worker

    # -- results (main thread) -------------------------------------------------------------
    def _show_result(self, result: StochasticResult | None) -> None:
        self.result = result
        if result is None:
            self.summary.value = ""
            self.summary.native.setToolTip("")
            self.plot.redraw()
            return
        lines = []
        for axis in result.samples:
            s = result.statistics(axis)
            lines.append(f"k_eff {axis} = {s['mean']:.5g} +- {s['sem']:.2g} (s.e.); 95 % of "
                         f"samples in {s['low']:.5g} .. {s['high']:.5g}")
        self.summary.value = "\n".join(lines)
        self.summary.native.setToolTip(result.describe())
        self.plot.redraw()

    def _draw_figure(self, figure: Figure) -> None:
        figure.clear()
        if self.result is not None:
            self.result.figure(figure)
