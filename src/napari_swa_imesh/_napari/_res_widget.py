"""RES widget: tile-moment statistics against scale (Figure 2.14 layout) and the scale pick."""

from __future__ import annotations

from typing import TYPE_CHECKING

from qtpy.QtCore import Signal
from qtpy.QtWidgets import (QFormLayout, QHBoxLayout, QLabel, QPushButton, QScrollArea,
                            QSpinBox, QVBoxLayout, QWidget)

from ..segmentation import plot_res, res_statistics
from . import _samples_layer as sl
from ._layers import SCALE_KEY, LayerCombo, theme_colors
from ._tasks import TaskPanel, notify_error

if TYPE_CHECKING:
    import napari

    from ..segmentation import ResStatistics

__all__ = ["ResWidget"]


class ResWidget(QWidget):
    """Plots of tile statistics against scale per material; choose the scale to classify at.

    Click a panel or use the spin box to choose a scale; the suggested RES is the dashed
    line, the chosen scale the solid one.

    Signals
    -------
    scale_chosen(int)
        The user chose a scale (also stored in the samples layer's metadata).
    """

    scale_chosen = Signal(int)

    def __init__(self, napari_viewer: "napari.viewer.Viewer", parent: QWidget | None = None):
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
        from matplotlib.figure import Figure

        super().__init__(parent)
        self.viewer = napari_viewer
        self.stats: ResStatistics | None = None
        self.image_combo = LayerCombo(self.viewer, ("Image",))
        self.samples_combo = LayerCombo(self.viewer, ("Shapes",), accept=sl.is_samples_layer)
        self.max_scale_spin = QSpinBox()
        self.max_scale_spin.setRange(-1, 16)
        self.max_scale_spin.setValue(-1)
        self.max_scale_spin.setSpecialValueText("auto")
        self.max_scale_spin.setToolTip("Largest scale to compute; auto: the largest at which "
                                       "some material still has 2^d tiles.")
        self.compute_button = QPushButton("Compute RES statistics")
        self.compute_button.clicked.connect(self.compute)
        self.scale_spin = QSpinBox()
        self.scale_spin.setRange(0, 16)
        self.scale_spin.setEnabled(False)
        self.scale_spin.setToolTip("Scale j to classify at (tiles of 2^j pixels per axis); "
                                   "or click a panel of the plot.")
        self.scale_spin.valueChanged.connect(self._on_scale_spin)
        self.reason = QLabel("Compute the statistics of the sample boxes to see where they "
                             "settle with scale.")
        self.reason.setWordWrap(True)

        self.figure = Figure(figsize=(6, 8))
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.canvas.setMinimumSize(360, 480)
        self.canvas.mpl_connect("button_press_event", self._on_click)
        scroll = QScrollArea()
        scroll.setWidget(self.canvas)
        scroll.setWidgetResizable(True)
        self.tasks = TaskPanel()

        form = QFormLayout()
        form.addRow("image", self.image_combo)
        form.addRow("samples", self.samples_combo)
        form.addRow("max scale", self.max_scale_spin)
        row = QHBoxLayout()
        row.addWidget(QLabel("chosen scale j"))
        row.addWidget(self.scale_spin)
        row.addStretch(1)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(self.compute_button)
        layout.addWidget(self.tasks)
        layout.addLayout(row)
        layout.addWidget(self.reason)
        layout.addWidget(scroll, 1)
        self.samples_combo.currentTextChanged.connect(self._on_samples_layer_selected)
        self._on_samples_layer_selected()
        self.viewer.events.theme.connect(self._on_theme)

    def _on_theme(self, event=None) -> None:
        try:
            self._draw()
        except RuntimeError:  # the Qt side is gone; napari drops us with the Python side
            pass

    def _on_samples_layer_selected(self, *_) -> None:
        layer = self.samples_combo.layer()
        if layer is not None:
            image_name = layer.metadata.get(sl.SAMPLES_KEY)
            if image_name and image_name in self.viewer.layers:
                self.image_combo.select(self.viewer.layers[image_name])

    def select_layers(self, image=None, samples=None) -> None:
        """Point the widget at these layers (the workflow keeps its tabs in step)."""
        if samples is not None:
            self.samples_combo.select(samples)
        if image is not None:
            self.image_combo.select(image)

    def compute(self):
        """Compute the RES statistics of the samples in a worker; plot them when done."""
        image, layer = self.image_combo.layer(), self.samples_combo.layer()
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
        except ValueError as exc:
            notify_error(f"cannot compute the RES: {exc}")
            return None
        max_scale = self.max_scale_spin.value()
        max_scale = None if max_scale < 0 else max_scale

        def steps():
            yield 0, 1, "tile moments of every sample box at every scale"
            stats = res_statistics(data, samples, max_scale=max_scale)
            yield 1, 1, "done"
            return stats

        return self.tasks.run(steps, title="RES statistics", total=1, on_result=self.show_stats)

    def show_stats(self, stats: "ResStatistics") -> None:
        """Plot `stats` and offer its scales; the suggested RES becomes the chosen scale."""
        self.stats = stats
        self.scale_spin.blockSignals(True)
        self.scale_spin.setRange(int(stats.scales.min()), int(stats.scales.max()))
        layer = self.samples_combo.layer()
        previous = None if layer is None else layer.metadata.get(SCALE_KEY)
        start = previous if previous is not None and previous <= stats.scales.max() \
            else stats.suggested_scale
        self.scale_spin.setValue(int(start if start is not None else stats.scales.max()))
        self.scale_spin.setEnabled(True)
        self.scale_spin.blockSignals(False)
        per_material = ", ".join(
            f"{name}: {stats.material_res.get(m) if stats.material_res.get(m) is not None else 'not settled'}"
            for m, name in zip(stats.materials, stats.names))
        self.reason.setText(f"Suggested RES: {stats.suggested_scale} ({stats.reason}) "
                            f"Per material: {per_material}.")
        self.choose_scale(self.scale_spin.value())

    def _draw(self) -> None:
        if self.stats is None:
            return
        dark, background, _ = theme_colors(self.viewer)
        plot_res(self.stats, figure=self.figure, selected_scale=self.scale_spin.value(),
                 dark=dark)
        # match the dock exactly (plot_res knows only light and dark)
        self.figure.set_facecolor(background)
        for ax in self.figure.axes:
            ax.set_facecolor(background)
        self.canvas.draw_idle()

    def choose_scale(self, scale: int) -> None:
        """Make `scale` the chosen one: mark it, store it with the samples, tell the others."""
        scale = int(scale)
        if self.scale_spin.value() != scale:
            self.scale_spin.setValue(scale)   # comes back here through the spin box
            return
        layer = self.samples_combo.layer()
        if layer is not None:
            layer.metadata[SCALE_KEY] = scale
        self._draw()
        self.scale_chosen.emit(scale)

    def _on_scale_spin(self, value: int) -> None:
        self.choose_scale(value)

    def _on_click(self, event) -> None:
        if self.stats is None or event.inaxes is None or event.xdata is None:
            return
        scales = self.stats.scales
        self.choose_scale(int(scales[abs(scales - event.xdata).argmin()]))
