"""RES widget: tile-moment statistics against scale (Figure 2.14 layout) and the scale pick."""

from __future__ import annotations

from typing import TYPE_CHECKING

from magicgui.widgets import ComboBox, Container, PushButton, SpinBox
from qtpy.QtCore import Signal
from qtpy.QtWidgets import QWidget

from ..segmentation import plot_res, res_statistics
from . import _samples_layer as sl
from ._dock import fit_dock, scroll_body, wrapped_label
from ._help import explain_terms
from ._layers import layer_picker, pick
from ._plots import ThemedFigure, dark_theme
from ._tasks import TaskPanel, notify_error, notify_warning

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    import napari

    from ..segmentation import ResStatistics

__all__ = ["ResWidget"]


class ResWidget(QWidget):
    """Plots of tile statistics against scale per material; choose the scale to classify at.

    Click a panel or use the spin box to choose a scale; the suggested RES is the dashed
    line, the chosen scale the solid one.

    The statistics remember the fingerprint of the samples they were computed on. When the
    boxes, materials or image change (napari layer events, or another layer picked), the
    plot is marked out of date: the chosen-scale line is removed, the scale cannot be
    chosen, and the stored choice no longer counts (see :func:`._samples_layer.chosen_scale`)
    until the statistics are computed again.

    Signals
    -------
    scale_chosen(int)
        The user chose a scale (also stored in the samples layer's metadata).
    stale_changed(bool)
        The statistics went out of date (True) or match the samples again (False).
    """

    scale_chosen = Signal(int)
    stale_changed = Signal(bool)

    def __init__(self, napari_viewer: napari.viewer.Viewer, parent: QWidget | None = None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.stats: ResStatistics | None = None
        self.stats_fingerprint: str | None = None   # of the samples `stats` were computed on
        self.stale = False
        self.method = "recommended"    # the classifier the suggestion is capped for
        self._watcher = sl.SamplesWatcher(self._check_stale)
        self.image_combo = layer_picker(self.viewer, "Image", label="image")
        self.samples_combo = layer_picker(self.viewer, "Shapes", label="samples",
                                          accept=sl.is_samples_layer)
        self.max_scale = ComboBox(
            label="max scale", choices=[("auto", None)] + [(str(j), j) for j in range(17)],
            tooltip="Largest scale to compute; auto: the largest at which some material "
                    "still has 2^d tiles.")
        self.compute_button = PushButton(text="Compute RES statistics")
        self.scale_spin = SpinBox(label="chosen scale j", min=0, max=16, enabled=False,
                                  tooltip="Scale j to classify at (tiles of 2^j pixels per "
                                          "axis); or click a panel of the plot.")
        self.reason = wrapped_label("Compute the statistics of the sample boxes to see where "
                                    "they settle with scale.")
        self.plot = ThemedFigure(self.viewer, self._draw_figure, min_height=360)
        self.plot.canvas.mpl_connect("button_press_event", self._on_click)
        self.tasks = TaskPanel()

        layout = scroll_body(self)
        layout.addWidget(Container(widgets=[self.image_combo, self.samples_combo,
                                            self.max_scale, self.compute_button]).native)
        layout.addWidget(self.tasks)
        layout.addWidget(Container(widgets=[self.scale_spin]).native)
        layout.addWidget(self.reason.native)
        layout.addWidget(self.plot, 1)
        fit_dock(self)
        self.compute_button.changed.connect(self.compute)
        self.scale_spin.changed.connect(self.choose_scale)
        self.samples_combo.changed.connect(self._on_samples_layer_selected)
        self.image_combo.changed.connect(self._on_image_selected)
        self._on_samples_layer_selected()
        explain_terms(self)

    @property
    def figure(self) -> Figure:
        return self.plot.figure

    @property
    def canvas(self):
        return self.plot.canvas

    def _on_samples_layer_selected(self, *_) -> None:
        layer = self.samples_combo.value
        if layer is not None:
            image_name = layer.metadata.get(sl.SAMPLES_KEY)
            if image_name and image_name in self.viewer.layers:
                pick(self.image_combo, self.viewer.layers[image_name])
        self._on_image_selected()

    def _on_image_selected(self, *_) -> None:
        self._watcher.watch(self.samples_combo.value, self.image_combo.value)
        self._check_stale()

    def current_fingerprint(self) -> str | None:
        """Fingerprint of the samples and image selected now (None if they cannot be read)."""
        layer, image = self.samples_combo.value, self.image_combo.value
        if layer is None or image is None or layer.ndim != image.ndim:
            return None
        try:
            return sl.samples_fingerprint(layer, image)
        except ValueError:
            return None

    def _check_stale(self) -> None:
        """Mark the statistics out of date when the samples differ from theirs."""
        if self.stats is None:
            return
        stale = self.current_fingerprint() != self.stats_fingerprint
        if stale == self.stale:
            return
        self.stale = stale
        self.scale_spin.enabled = not stale
        self._show_reason()
        self._draw()
        self.stale_changed.emit(stale)

    def _show_reason(self) -> None:
        stats = self.stats
        settled = {m: stats.material_res.get(m) for m in stats.materials}
        per_material = ", ".join(
            f"{name}: {'not settled' if settled[m] is None else settled[m]}"
            for m, name in zip(stats.materials, stats.names))
        text = (f"Suggested RES: {stats.suggested_scale} ({stats.reason}) "
                f"Per material: {per_material}.")
        if self.stale:
            text = ("OUT OF DATE: the sample boxes, materials or image changed since these "
                    "statistics were computed; the scale chosen on them no longer applies. "
                    "Press 'Compute RES statistics' again. (Were: " + text + ")")
        self.reason.value = text

    def select_layers(self, image=None, samples=None) -> None:
        """Point the widget at these layers (the workflow keeps its tabs in step)."""
        if samples is not None:
            pick(self.samples_combo, samples)
        if image is not None:
            pick(self.image_combo, image)

    def compute(self):
        """Compute the RES statistics of the samples in a worker; plot them when done.

        The statistics are stamped with the fingerprint of the samples read here, so
        edits made while the worker runs show them out of date at once.
        """
        image, layer = self.image_combo.value, self.samples_combo.value
        if image is None:
            notify_error("no image layer: open an image (or File > Open Sample) and pick it "
                         "in the RES widget.")
            return None
        if layer is None:
            notify_error("no samples layer: draw sample boxes in the samples widget first.")
            return None
        try:
            data = sl.image_array(image)
            samples, _ = sl.samples_from_layer(layer, image)
            fingerprint = sl.samples_fingerprint(layer, image)
        except ValueError as exc:
            notify_error(f"cannot compute the RES: {exc}")
            return None
        max_scale, method = self.max_scale.value, self.method

        def steps():
            yield 0, 1, "tile moments of every sample box at every scale"
            stats = res_statistics(data, samples, max_scale=max_scale, method=method)
            yield 1, 1, "done"
            return stats

        return self.tasks.run(steps, title="RES statistics",
                              on_result=lambda stats: self.show_stats(stats, fingerprint))

    def show_stats(self, stats: ResStatistics, fingerprint: str | None = None) -> None:
        """Plot `stats` and offer its scales; the suggested RES becomes the chosen scale.

        Parameters
        ----------
        stats : ResStatistics
        fingerprint : str, optional
            :func:`._samples_layer.samples_fingerprint` of the samples `stats` were computed
            on; by default that of the samples selected now.
        """
        self.stats = stats
        self.stats_fingerprint = fingerprint if fingerprint is not None \
            else self.current_fingerprint()
        self.stale = self.current_fingerprint() != self.stats_fingerprint
        spin = self.scale_spin
        layer, image = self.samples_combo.value, self.image_combo.value
        choice = None if layer is None else sl.scale_choice(layer, image)
        # keep an earlier choice only if it was made on these very samples
        previous = choice.scale if choice is not None and choice.fresh and not self.stale \
            else None
        start = previous if previous is not None and previous <= stats.scales.max() \
            else stats.suggested_scale
        with spin.changed.blocked():
            spin.range = (int(stats.scales.min()), int(stats.scales.max()))
            spin.value = int(start if start is not None else stats.scales.max())
        spin.enabled = not self.stale
        self._show_reason()
        if self.stale:
            self._draw()
            self.stale_changed.emit(True)
        else:
            self.choose_scale(spin.value)

    def _draw(self) -> None:
        self.plot.redraw()

    def _draw_figure(self, figure: Figure) -> None:
        if self.stats is None:
            figure.clear()
            return
        figure.set_layout_engine("none")     # plot_res lays out once, tightly
        plot_res(self.stats, figure=figure, dark=dark_theme(self.viewer),
                 selected_scale=None if self.stale else self.scale_spin.value)
        if figure.get_suptitle():    # wrapped to the dock's width instead of cut at its edges
            figure.suptitle(figure.get_suptitle(), fontsize=10, wrap=True)
        # see the dock through the figure, as napari-matplotlib's own plots do
        figure.set_facecolor("none")
        for ax in figure.axes:
            ax.set_facecolor("none")
            if self.stale:      # grey the panels: these numbers belong to other samples
                for artist in ax.lines + ax.collections:
                    artist.set_alpha(0.25)
        if self.stale:
            figure.suptitle("OUT OF DATE: the samples changed; compute the RES again",
                            color="#ff8c69", fontsize=10)
        # constrained layout keeps the figure title clear of the column titles
        figure.set_layout_engine("constrained")

    def choose_scale(self, scale: int) -> None:
        """Make `scale` the chosen one: mark it, store it with the samples, tell the others.

        Refused (with a warning) while the statistics are out of date.
        """
        scale = int(scale)
        if self.stale:
            notify_warning("the RES statistics are out of date (the samples changed); "
                           "compute them again before choosing a scale.")
            return
        if self.scale_spin.value != scale:
            self.scale_spin.value = scale     # comes back here through the spin box
            return
        layer = self.samples_combo.value
        if layer is not None and self.stats_fingerprint is not None:
            sl.store_chosen_scale(layer, scale, fingerprint=self.stats_fingerprint,
                                  suggested=self.stats.suggested_scale)
        self._draw()
        self.scale_chosen.emit(scale)

    def _on_click(self, event) -> None:
        if self.stats is None or event.inaxes is None or event.xdata is None:
            return
        scales = self.stats.scales
        self.choose_scale(int(scales[abs(scales - event.xdata).argmin()]))
