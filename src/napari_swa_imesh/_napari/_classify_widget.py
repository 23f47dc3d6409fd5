"""Classify widget: SWA segmentation of an image layer into a Labels layer that overlays it."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from magicgui.widgets import ComboBox, Container, SpinBox
from qtpy.QtCore import Signal
from qtpy.QtWidgets import QFileDialog, QTableWidget, QTableWidgetItem, QWidget

from ..segmentation import (
    CLASSIFIERS,
    FEATURE_SETS,
    MOMENT_NAMES,
    dice_scores,
    load_model,
    segment_steps,
    tile_placement,
)
from . import _samples_layer as sl
from ._chunked_classify import add_lazy_labels, chunked_steps, lazy_level0
from ._dock import Fold, button, fit_dock, scroll_body, side_by_side, wrapped_label
from ._help import explain_terms
from ._layers import (
    AFFINE_KEY,
    block_affine,
    is_layer,
    labels_colormap,
    layer_picker,
    layer_spacing,
    material_palette,
    pick,
)
from ._tasks import TaskPanel, notify_error, notify_info, notify_warning

if TYPE_CHECKING:
    import napari

    from ..segmentation import SegmentationResult, SWAModel

__all__ = ["ClassifyWidget", "SEGMENTATION_KEY", "OUTPUT_FULL", "OUTPUT_TILES",
           "METHOD_RECOMMENDED", "METHOD_REFERENCE", "run_summary"]

SEGMENTATION_KEY = "swa_imesh_segmentation"   # Labels metadata: the run's summary
OUTPUT_FULL = "full resolution"
OUTPUT_TILES = "one label per tile"
METHOD_RECOMMENDED = "recommended (multi-scale, full resolution)"
METHOD_REFERENCE = "reference (one tile scale)"
SUGGESTED = "suggested RES"


class ClassifyWidget(QWidget):
    """Fit a classifier on the sample boxes (or apply a saved model) and label every tile.

    The scale note under the settings says which scale the next run uses and where it
    comes from: set in this panel, chosen on the RES tab for these very boxes, or the
    suggested RES of the current boxes (computed in the run, as the command line does).
    A scale chosen on the RES tab for boxes that have changed since is never used: the
    panel drops it, says so, and classifies at the suggested RES of the current boxes.
    With the recommended method it also says, before the run, when a material's boxes
    are too small for the scale's windows (:meth:`Samples.window_limit`).

    Signals
    -------
    labels_ready(object)
        A Labels layer was created or updated with a segmentation.
    """

    labels_ready = Signal(object)

    def __init__(self, napari_viewer: napari.viewer.Viewer, parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.result: SegmentationResult | None = None
        self.dice: dict[int, float] | None = None
        self.loaded_model: SWAModel | None = None
        self._scale_from_res: int | None = None   # scale set from the RES choice
        self._setting_scale = False
        self._dropped_scale: int | None = None    # a RES choice dropped as stale
        self._watcher = sl.SamplesWatcher(self.update_scale_note)
        self.image_combo = layer_picker(self.viewer, "Image", label="image")
        self.samples_combo = layer_picker(self.viewer, "Shapes", label="samples",
                                          accept=sl.is_samples_layer)
        self.method_combo = ComboBox(
            label="method", choices=[METHOD_RECOMMENDED, METHOD_REFERENCE],
            tooltip="recommended: per-pixel statistics at every scale up to the RES, refined "
                    "at boundaries, MRF-smoothed and bias-corrected (full-resolution labels); "
                    "reference: the dissertation's method, one feature set and classifier on "
                    "tiles of one scale.")
        self.feature_combo = ComboBox(label="feature set", choices=list(FEATURE_SETS),
                                      tooltip="Table 2.1: F1 moments, F2 entropy, F3 "
                                              "correlation lengths, F4..F7 their unions.")
        self.classifier_combo = ComboBox(
            label="classifier", choices=[c.upper() for c in CLASSIFIERS],
            tooltip="GM: Gaussian maximum likelihood; MD: nearest neighbour; LVQ: learning "
                    "vector quantisation.")
        self.scale_combo = ComboBox(label="scale j", choices=[(SUGGESTED, None)] + [
            (str(j), j) for j in range(17)])
        self.scale_note = wrapped_label()
        self.sieve_spin = SpinBox(label="sieve (tiles, 0 = off)", min=0, max=1_000_000,
                                  tooltip="Merge connected regions smaller than this many "
                                          "tiles into their surroundings.")
        self.output_combo = ComboBox(label="output", choices=[OUTPUT_FULL, OUTPUT_TILES])
        self.truth_combo = layer_picker(
            self.viewer, "Labels", label="truth (Dice)", none_text="(none)",
            tooltip="A ground truth to report Dice against (optional).")
        self.classify_button = button("Classify", self.classify)
        self.save_model_button = button("Save model...", self._on_save_model_clicked)
        self.load_model_button = button("Load model...", self._on_load_model_clicked)
        self.apply_model_button = button("Apply loaded model to image", self.apply_model)
        self.model_label = wrapped_label("no model loaded")
        self.scores = wrapped_label()
        self.signature_table = QTableWidget(0, 0)
        self.signature_table.setEditTriggers(QTableWidget.NoEditTriggers)
        self.export_button = button("Export signatures CSV...", self._on_export_clicked)
        for later in (self.save_model_button, self.apply_model_button, self.export_button):
            later.enabled = False
        self.tasks = TaskPanel()

        layout = scroll_body(self)
        layout.addWidget(Container(widgets=[
            self.image_combo, self.samples_combo, self.method_combo, self.feature_combo,
            self.classifier_combo, self.scale_combo]).native)
        layout.addWidget(Container(widgets=[self.sieve_spin, self.output_combo,
                                            self.truth_combo, self.classify_button]).native)
        layout.addWidget(self.tasks)
        layout.addWidget(self.scores.native)       # the run's result next to its button
        layout.addWidget(self.scale_note.native)
        layout.addWidget(wrapped_label("Material signatures (moments of the tiles of each "
                                       "material)").native)
        layout.addWidget(self.signature_table, 1)
        layout.addWidget(self.export_button.native)
        layout.addWidget(Fold("Model", [
            side_by_side(self.save_model_button, self.load_model_button), self.model_label,
            self.apply_model_button]))
        fit_dock(self)
        self.method_combo.changed.connect(self._on_method_changed)
        self.scale_combo.changed.connect(self._on_scale_combo)
        self.samples_combo.changed.connect(self._on_samples_layer_selected)
        self.image_combo.changed.connect(self._on_layers_changed)
        self._on_samples_layer_selected()
        self._on_method_changed()
        explain_terms(self)

    def _on_method_changed(self, *_) -> None:
        # feature set and classifier belong to the reference method only
        reference = self.method_combo.value == METHOD_REFERENCE
        self.feature_combo.enabled = reference
        self.classifier_combo.enabled = reference
        self.scale_combo.tooltip = (
            "Tile scale j (tiles of 2^j px per axis); by default the scale chosen in the RES "
            "plots, else the suggested RES." if reference else
            "Largest scale the recommended method looks at (windows of 2^j+1 px); by default "
            "the scale chosen in the RES plots, else the suggested RES.")
        self.update_scale_note()

    # -- settings --------------------------------------------------------------------------
    def _on_samples_layer_selected(self, *_) -> None:
        layer = self.samples_combo.value
        if layer is not None:
            image_name = layer.metadata.get(sl.SAMPLES_KEY)
            if image_name and image_name in self.viewer.layers:
                pick(self.image_combo, self.viewer.layers[image_name])
            chosen = sl.chosen_scale(layer, self.image_combo.value)
            if chosen is not None:
                self.set_scale(chosen)
        self._on_layers_changed()

    def _on_layers_changed(self, *_) -> None:
        self._watcher.watch(self.samples_combo.value, self.image_combo.value)
        self.update_scale_note()

    def set_scale(self, scale: int) -> None:
        """Classify at `scale`, chosen on the RES tab (the workflow calls this).

        The scale is used only while the samples layer's stored choice (see
        :func:`._samples_layer.chosen_scale`) still matches the boxes and image.
        """
        self._set_scale_combo(int(scale))
        self._scale_from_res = int(scale)
        self._dropped_scale = None
        self.update_scale_note()

    def _set_scale_combo(self, value: int | None) -> None:
        self._setting_scale = True
        try:
            self.scale_combo.value = value
        finally:
            self._setting_scale = False

    def _on_scale_combo(self, value: int | None) -> None:
        if self._setting_scale:
            return
        self._scale_from_res = None          # typed here: the user's own choice
        self._dropped_scale = None
        self.update_scale_note()

    def resolve_scale(self) -> tuple[int | None, str]:
        """The scale the next run uses (None: the suggested RES) and where it comes from.

        Drops (resets to "suggested RES") a scale that came from a RES choice no longer
        matching the samples.
        """
        value = self.scale_combo.value
        if value is not None and self._scale_from_res == value:
            layer, image = self.samples_combo.value, self.image_combo.value
            choice = None if layer is None else sl.scale_choice(layer, image)
            if choice is not None and choice.fresh and choice.scale == value:
                return value, f"scale {value}, chosen on the RES tab for these sample boxes"
            self._dropped_scale, self._scale_from_res = value, None
            self._set_scale_combo(None)
            value = None
        if value is None:
            source = ("the suggested RES of the current sample boxes (computed when you "
                      "classify, as the command line does)")
            if self._dropped_scale is not None:
                source += (f"; scale {self._dropped_scale} chosen on the RES tab is not used: "
                           "it was chosen for other sample boxes or another image (they "
                           "changed since). Compute the RES again to choose a scale")
            return None, source
        return value, f"scale {value}, set in this panel"

    def window_warning(self, samples, scale: int | None) -> str | None:
        """The :meth:`Samples.window_limit` sentence for the recommended method at `scale`."""
        if scale is None or self.method_combo.value != METHOD_RECOMMENDED:
            return None
        limit = samples.window_limit(int(scale))
        return None if limit is None else limit[1]

    def update_scale_note(self) -> None:
        """Say which scale the next run uses, where it comes from, and what to enlarge."""
        scale, source = self.resolve_scale()
        text = f"Next run: {source}."
        layer, image = self.samples_combo.value, self.image_combo.value
        if scale is not None and layer is not None and image is not None \
                and layer.ndim == image.ndim:
            try:
                samples, _ = sl.samples_from_layer(layer, image)
            except ValueError:
                samples = None
            warning = None if samples is None else self.window_warning(samples, scale)
            if warning:
                text += f" Warning: {warning}."
        self.scale_note.value = text

    def select_layers(self, image=None, samples=None) -> None:
        if samples is not None:
            pick(self.samples_combo, samples)
        if image is not None:
            pick(self.image_combo, image)

    def _truth(self, image_shape):
        truth = self.truth_combo.value
        if truth is None:
            return None
        if tuple(truth.data.shape) != tuple(image_shape):
            notify_warning(f"the truth {truth.name!r} has shape {truth.data.shape}, the image "
                           f"{tuple(image_shape)}; Dice is skipped. Pick the image's truth.")
            return None
        return np.asarray(truth.data)

    # -- runs ------------------------------------------------------------------------------
    def classify(self):
        """Fit on the samples and classify the image, in a worker."""
        image, layer = self.image_combo.value, self.samples_combo.value
        if image is None:
            notify_error("no image layer to classify: open an image (or File > Open Sample) "
                         "and pick it in the classify widget.")
            return None
        if layer is None:
            notify_error("no samples layer: draw sample boxes per material in the samples "
                         "widget (or import a samples file) before classifying.")
            return None
        scale, source = self.resolve_scale()
        try:
            data = sl.image_array(image)
            samples, report = sl.samples_from_layer(layer, image, scale=scale)
        except ValueError as exc:
            notify_error(f"cannot classify: {exc}")
            return None
        if self._dropped_scale is not None:
            notify_warning(f"classifying at {source}.")
        window = self.window_warning(samples, scale)
        self.scale_note.value = f"Next run: {source}." + (f" Warning: {window}." if window else "")
        if window:
            notify_warning(window)
        small = [i for i, f in enumerate(report.flags) if any(x.startswith("too small at")
                                                               for x in f)]
        if small:
            notify_warning(
                f"{len(small)} sample box(es) ({', '.join(str(i + 1) for i in small)}) are "
                f"smaller than one tile at scale {scale} and give no training tile; enlarge "
                "them or choose a smaller scale.")
        truth = self._truth(data.shape)
        options = dict(scale=scale, sieve=self.sieve_spin.value, spacing=layer_spacing(image))
        if self.method_combo.value == METHOD_REFERENCE:
            options.update(method="reference", feature_set=self.feature_combo.value,
                           classifier=self.classifier_combo.value.lower())
        else:
            options.update(method="recommended")

        def steps():
            result = yield from segment_steps(data, samples, **options)
            dice = None if truth is None else dice_scores(result.labels, truth)
            return result, dice

        def show(out):
            self._show_result(image, *out)
            self._show_scale_used(out[0], samples, source, window)

        return self.tasks.run(steps, title="SWA classification",
                              on_result=show)

    def _show_scale_used(self, result, samples, source: str, window: str | None) -> None:
        """After a run: which scales ran, why, and every warning about them, once each."""
        self._dropped_scale = None
        if result.res is not None and result.res.suggested_scale is not None \
                and source.startswith("the suggested RES"):
            source = f"the suggested RES of these boxes, {result.res.suggested_scale}"
        if result.method == "recommended":
            top = result.model.scores.get("top_scale")
            text = (f"Last run: labels from scales {', '.join(map(str, result.scales))}; "
                    f"coarse scale {result.scale} picked by cross-validation"
                    + (f" among 0..{top}" if top is not None else "")
                    + f". Largest scale asked: {source}.")
        else:
            text = f"Last run: tiles of scale {result.scale}: {source}."
        later = window or self.window_warning(samples, result.scale)
        notes: list[str] = []
        for note in ([later] if later else []) + list(self.tasks.warnings):
            note = note.rstrip(".")
            # the fit's warning repeats the panel's sentence and adds what it did: keep one
            notes = [n for n in notes if n not in note]
            if not any(note in n for n in notes):
                notes.append(note)
        if notes:
            text += " Warning: " + " ".join(n + "." for n in notes)
        self.scale_note.value = text

    def apply_model(self):
        """Apply the loaded model to the selected image, in a worker."""
        image = self.image_combo.value
        if self.loaded_model is None:
            notify_error("no model loaded: press 'Load model...' and pick a .npz model file.")
            return None
        if image is None:
            notify_error("no image layer to apply the model to: open one and pick it.")
            return None
        lazy = lazy_level0(image)
        if lazy is not None:        # a Dask/Zarr layer: chunk by chunk, never loaded whole
            return self.tasks.run(lambda: chunked_steps(lazy, self.loaded_model),
                                  title="Applying the model chunk by chunk",
                                  on_result=lambda out: add_lazy_labels(
                                      self.viewer, image, out[0], self.loaded_model, out[1]))
        try:
            data = sl.image_array(image)
        except ValueError as exc:
            notify_error(f"cannot apply the model: {exc}")
            return None
        model, sieve, truth = self.loaded_model, self.sieve_spin.value, self._truth(data.shape)
        if model.spacing and not np.allclose(model.spacing, layer_spacing(image)):
            notify_warning(f"the model was trained on voxels of {list(model.spacing)}, the "
                           f"image has {list(layer_spacing(image))}; tiles will cover other "
                           "physical sizes, so check the result.")

        def steps():
            result = yield from segment_steps(data, model=model, sieve=sieve)
            dice = None if truth is None else dice_scores(result.labels, truth)
            return result, dice

        return self.tasks.run(steps, title="Applying the model",
                              on_result=lambda out: self._show_result(image, *out))

    # -- results (main thread) ---------------------------------------------------------------
    def _show_result(self, image, result: SegmentationResult, dice) -> None:
        self.result, self.dice = result, dice
        materials = result.model.materials
        names = {m.label: m.name for m in materials}
        colors = material_palette(names, {m.label: m.color for m in materials})
        spacing = layer_spacing(image)
        tiles = self.output_combo.value == OUTPUT_TILES
        if tiles:
            data = result.tile_labels
            layer_scale, offset = tile_placement(result.scale, spacing, image.ndim)
            translate = tuple(t + o for t, o in zip(image.translate, offset))
        else:
            data, layer_scale, translate = result.labels, spacing, tuple(image.translate)
        name = f"{image.name} SWA labels"
        metadata = {SEGMENTATION_KEY: result.summary(), "material_names": names,
                    "swa_imesh_source": image.name,
                    AFFINE_KEY: block_affine(image, 1 << result.scale if tiles else 1)}
        affine = image.affine.affine_matrix               # a NIfTI image's world placement
        if name in self.viewer.layers and \
                is_layer(self.viewer.layers[name], "Labels"):
            labels = self.viewer.layers[name]
            labels.data = data
            labels.scale, labels.translate, labels.affine = layer_scale, translate, affine
            labels.metadata.update(metadata)
            labels.colormap = labels_colormap(colors)
        else:
            labels = self.viewer.add_labels(data, name=name, scale=layer_scale,
                                            translate=translate, affine=affine, opacity=0.5,
                                            colormap=labels_colormap(colors), metadata=metadata)
        self.scores.value = run_summary(result, dice, names)
        self._show_signatures(result.signatures)
        self.save_model_button.enabled = True
        self.export_button.enabled = True
        self.labels_ready.emit(labels)

    def _show_signatures(self, signatures: list[dict]) -> None:
        columns = ["name", "tiles"] + [f"{m}_{s}" for m in MOMENT_NAMES for s in ("mean", "std")]
        self.signature_table.clear()
        self.signature_table.setColumnCount(len(columns))
        self.signature_table.setRowCount(len(signatures))
        self.signature_table.setHorizontalHeaderLabels(
            [c.replace("_", " ") for c in columns])
        for row, signature in enumerate(signatures):
            for column, key in enumerate(columns):
                value = signature.get(key, "")
                text = f"{value:.4g}" if isinstance(value, float) else str(value)
                self.signature_table.setItem(row, column, QTableWidgetItem(text))
        self.signature_table.resizeColumnsToContents()

    # -- files -----------------------------------------------------------------------------
    def export_signatures(self, path) -> None:
        """Write the material signatures of the last run as CSV."""
        from ..segmentation import write_signatures_csv

        if self.result is None:
            notify_error("classify first: the signatures come from a classification.")
            return
        try:
            write_signatures_csv(self.result.signatures, path, force=True)
        except (ValueError, OSError) as exc:
            notify_error(f"could not write the signatures: {exc}")
            return
        notify_info(f"material signatures written to {path}")

    def save_model(self, path) -> None:
        """Save the model of the last run (.npz, no pickles)."""
        if self.result is None:
            notify_error("classify first: there is no fitted model to save yet.")
            return
        try:
            self.result.model.save(path, force=True)
        except (ValueError, OSError) as exc:
            notify_error(f"could not save the model: {exc}")
            return
        notify_info(f"model saved to {path}")

    def load_model(self, path) -> None:
        """Load a saved model; 'Apply loaded model' then classifies the selected image."""
        try:
            model = load_model(path)
        except (ValueError, OSError) as exc:
            notify_error(f"could not load the model: {exc}")
            return
        self.loaded_model = model
        self.apply_model_button.enabled = True
        names = ", ".join(m.name for m in model.materials)
        self.model_label.value = (
            f"loaded: {model.ndim}-D, scale {model.scale}, {model.feature_set}, "
            f"{model.classifier_name.upper()}, materials {names}")

    def _on_export_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export signatures", "signatures.csv",
                                              "CSV (*.csv)")
        if path:
            self.export_signatures(path)

    def _on_save_model_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save model", "model.npz",
                                              "SWA model (*.npz)")
        if path:
            self.save_model(path if path.endswith(".npz") else path + ".npz")

    def _on_load_model_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load model", "", "SWA model (*.npz)")
        if path:
            self.load_model(path)


def run_summary(result: SegmentationResult, dice: dict[int, float] | None,
                names: dict[int, str]) -> str:
    """One line about a classification: method and scales, scores, Dice, time.

    The library's ``SegmentationResult.describe()`` (what the command line and the demo
    print), with the Dice against a truth layer and the time.
    """
    # warnings are in the task panel, signatures in the table below (a laptop's fold)
    lines = result.describe(notes=False).splitlines()
    parts = ["; ".join(line for line in lines if not line.startswith("  "))]
    if dice:
        parts.append("Dice: " + ", ".join(
            f"{names.get(k, k)} {v:.3f}" for k, v in dice.items() if not math.isnan(v)))
    parts.append(f"{result.seconds.get('total', float('nan')):.2f} s")
    return "; ".join(parts)
