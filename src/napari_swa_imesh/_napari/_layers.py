"""Small adapters between napari layers and the library: colours, spacing, placement, combos."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from qtpy.QtWidgets import QComboBox

if TYPE_CHECKING:
    import napari

__all__ = ["PALETTE", "material_palette", "labels_colormap", "LayerCombo", "theme_colors",
           "layer_spacing", "index_to_layer_data", "mesh_translate", "SAMPLES_KEY",
           "MATERIALS_KEY", "EXTENT_KEY", "MESH_KEY", "SCALE_KEY"]

# tab10 without grey: distinct on dark and light napari themes
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#bcbd22", "#17becf")

# metadata keys the widgets share through layers (so each widget also works on its own)
SAMPLES_KEY = "swa_imesh_samples"      # on a Shapes layer: name of the image it samples
MATERIALS_KEY = "swa_imesh_materials"  # on a Shapes layer: list of {label, name, color}
SCALE_KEY = "swa_imesh_scale"          # on a Shapes layer: the scale chosen from the RES
EXTENT_KEY = "swa_imesh_extent_of"     # on the 3-D extent overlay: its samples layer name
MESH_KEY = "swa_imesh_mesh"            # on a Surface layer: the real Mesh (for the writer)


def default_color(label: int) -> str:
    """Colour of material `label` when none was given."""
    return PALETTE[(int(label) - 1) % len(PALETTE)]


def material_palette(names: dict[int, str], colors: dict[int, str | None] | None = None
                     ) -> dict[int, str]:
    """A colour per material label: the given one, else the palette's."""
    colors = colors or {}
    return {int(k): colors.get(k) or default_color(k) for k in names}


def labels_colormap(colors: dict[int, str]):
    """napari DirectLabelColormap: each material its colour, 0 and unknown transparent."""
    from napari.utils.colormaps import DirectLabelColormap

    color_dict = {None: "transparent", 0: "transparent"}
    color_dict.update({int(k): v for k, v in colors.items()})
    return DirectLabelColormap(color_dict=color_dict)


def theme_colors(viewer: "napari.viewer.Viewer") -> tuple[bool, str, str]:
    """(dark, background hex, text hex) of the viewer's theme, for matplotlib figures."""
    from napari.utils.theme import get_theme

    try:
        theme = get_theme(viewer.theme)
        bg, fg = theme.background.as_hex(), theme.text.as_hex()
    except (ValueError, KeyError, AttributeError):
        bg, fg = "#262930", "#f0f1f2"
    rgb = np.array([int(bg[i:i + 2], 16) for i in (1, 3, 5)]) / 255
    return bool(rgb @ [0.299, 0.587, 0.114] < 0.5), bg, fg


def layer_spacing(layer) -> tuple[float, ...]:
    """Voxel spacing of a layer: its ``scale``."""
    return tuple(float(s) for s in layer.scale)


def index_to_layer_data(coords: np.ndarray, source, target) -> np.ndarray:
    """Map data coordinates of layer `source` to data coordinates of layer `target`.

    Uses each layer's scale and translate (rotation, shear and affine are not used by the
    plugin's layers).
    """
    world = np.asarray(coords, float) * np.asarray(source.scale) + np.asarray(source.translate)
    return (world - np.asarray(target.translate)) / np.asarray(target.scale)


def mesh_translate(labels_layer) -> tuple[float, ...]:
    """Translate of a Surface (scale 1) that puts a mesh of `labels_layer` over it.

    Mesh points are pixel-corner index times spacing; napari puts pixel i's centre at
    ``i * scale + translate``, so corner 0 is half a pixel before it.
    """
    return tuple(float(t - s / 2) for t, s in zip(labels_layer.translate, labels_layer.scale))


class LayerCombo(QComboBox):
    """A combo box of the viewer's layers of some types, kept up to date.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
    layer_types : tuple of str
        napari layer class names, e.g. ``("Image",)``.
    accept : callable, optional
        Further filter on layers (e.g. not the 3-D extent overlay).
    none_text : str, optional
        When given, a first entry with this text selects no layer.
    """

    def __init__(self, viewer: "napari.viewer.Viewer", layer_types: tuple[str, ...], *,
                 accept=None, none_text: str | None = None, parent=None):
        super().__init__(parent)
        self.viewer = viewer
        self.layer_types = layer_types
        self.accept = accept
        self.none_text = none_text
        events = viewer.layers.events
        for emitter in (events.inserted, events.removed, events.reordered):
            emitter.connect(self._on_layers_changed)
        for layer in viewer.layers:
            layer.events.name.connect(self._on_layers_changed)
        self.refresh()

    def _on_layers_changed(self, event=None) -> None:
        if event is not None and getattr(event, "type", "") == "inserted":
            event.value.events.name.connect(self._on_layers_changed)
        try:
            self.refresh()
        except RuntimeError:  # the Qt side was deleted before Python's: stop listening
            events = self.viewer.layers.events
            for emitter in (events.inserted, events.removed, events.reordered):
                emitter.disconnect(self._on_layers_changed)

    def _layers(self) -> list:
        return [layer for layer in self.viewer.layers
                if type(layer).__name__ in self.layer_types
                and (self.accept is None or self.accept(layer))]

    def refresh(self) -> None:
        """Re-list the layers, keeping the current one selected if it still exists."""
        current = self.currentText()
        names = ([self.none_text] if self.none_text is not None else []) + \
            [layer.name for layer in self._layers()]
        self.blockSignals(True)
        self.clear()
        self.addItems(names)
        if current in names:
            self.setCurrentText(current)
        self.blockSignals(False)
        if self.currentText() != current:
            self.currentTextChanged.emit(self.currentText())

    def layer(self):
        """The selected layer, or None."""
        name = self.currentText()
        if not name or name == self.none_text or name not in self.viewer.layers:
            return None
        return self.viewer.layers[name]

    def select(self, layer) -> None:
        """Select `layer` (refreshing first, in case it was just added)."""
        self.refresh()
        index = self.findText(layer.name)
        if index >= 0:
            self.setCurrentIndex(index)
