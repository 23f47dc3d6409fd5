"""Small adapters between napari layers and the library: colours, spacing, placement, pickers."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import napari

__all__ = ["PALETTE", "material_palette", "labels_colormap", "layer_picker", "pick",
           "layer_spacing", "index_to_layer_data", "mesh_translate", "SAMPLES_KEY",
           "MATERIALS_KEY", "EXTENT_KEY", "MESH_KEY", "SCALE_KEY", "AFFINE_KEY",
           "placed_by_affine", "block_affine", "is_layer"]

# tab10 without grey: distinct on dark and light napari themes
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#bcbd22", "#17becf")

# metadata keys the widgets share through layers (so each widget also works on its own)
SAMPLES_KEY = "swa_imesh_samples"      # on a Shapes layer: name of the image it samples
MATERIALS_KEY = "swa_imesh_materials"  # on a Shapes layer: list of {label, name, color}
SCALE_KEY = "swa_imesh_scale"          # on a Shapes layer: the scale chosen from the RES
EXTENT_KEY = "swa_imesh_extent_of"     # on the 3-D extent overlay: its samples layer name
MESH_KEY = "swa_imesh_mesh"            # on a Surface layer: the real Mesh (for the writer)
AFFINE_KEY = "swa_imesh_affine"        # on a layer read from NIfTI: its index-to-world affine


def is_layer(layer, kind: str) -> bool:
    """Whether `layer` is a napari layer of `kind` (``"Shapes"``, ``"Labels"``, ...).

    By ``isinstance``, not by type name: napari hands a plugin's widgets the viewer and its
    layers through a ``PublicOnlyProxy``, whose type is the proxy's (docked from the Plugins
    menu, meshing again added a second mesh layer instead of updating the first).

    Parameters
    ----------
    layer : napari layer, its proxy, or None
    kind : str
        A class name of ``napari.layers``.

    Returns
    -------
    bool
    """
    import napari.layers

    return isinstance(layer, getattr(napari.layers, kind))


def default_color(label: int) -> str:
    """Colour of material `label` when none was given."""
    return PALETTE[(int(label) - 1) % len(PALETTE)]


def material_palette(names: dict[int, str], colors: dict[int, str | None] | None = None
                     ) -> dict[int, str]:
    """A colour per material label: the given one, else the palette's."""
    colors = colors or {}
    return {int(k): colors.get(k) or default_color(k) for k in names}


def labels_colormap(colors: dict[int, str]):
    """Napari DirectLabelColormap: each material its colour, 0 and unknown transparent."""
    from napari.utils.colormaps import DirectLabelColormap

    color_dict = {None: "transparent", 0: "transparent"}
    color_dict.update({int(k): v for k, v in colors.items()})
    return DirectLabelColormap(color_dict=color_dict)


def layer_spacing(layer) -> tuple[float, ...]:
    """Voxel spacing of a layer: its ``scale``."""
    return tuple(float(s) for s in layer.scale)


def placed_by_affine(layer) -> np.ndarray | None:
    """The NIfTI affine a layer was read with (``AFFINE_KEY``), while its scale is still
    the affine's voxel sizes; else None (mesh with the scale, in the image's frame)."""
    affine = layer.metadata.get(AFFINE_KEY)
    if affine is None:
        return None
    from ..mesh import voxel_sizes

    affine = np.asarray(affine, dtype=np.float64)
    if not np.allclose(voxel_sizes(affine, layer.ndim), layer.scale, rtol=1e-9):
        return None
    return affine


def block_affine(layer, step: int = 1) -> list | None:
    """``AFFINE_KEY`` of a grid of `step`-voxel blocks of `layer` (tile labels; 1: the same
    grid, :func:`~napari_swa_imesh.io.grid_affine`), from the layer's own; None when it has
    none."""
    from ..io import grid_affine

    affine = layer.metadata.get(AFFINE_KEY)
    return None if affine is None else grid_affine(affine, step, layer.ndim).tolist()


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


class _Follower:
    """Re-lists a picker's choices on layer-list events; held by the picker only, so the
    viewer's (weak) reference to it dies with the picker."""

    def __init__(self, viewer, combo):
        self.combo = combo
        events = viewer.layers.events
        self.emitters = (events.inserted, events.removed, events.reordered, events.renamed)
        for emitter in self.emitters:
            emitter.connect(self.reset)

    def reset(self, event=None) -> None:
        try:
            self.combo.reset_choices()
        except RuntimeError:  # the Qt side was deleted before Python's: stop listening
            for emitter in self.emitters:
                emitter.disconnect(self.reset)


def layer_picker(viewer: napari.viewer.Viewer, kind: str, *, label: str, accept=None,
                 none_text: str | None = None, tooltip: str | None = None):
    """A magicgui ComboBox of `viewer`'s layers of one type, kept in step with the layer list.

    napari's own layer pickers (a parameter annotated ``napari.layers.Image``) find their
    viewer by walking up the Qt parents, so they stay empty until docked; this one is bound
    to `viewer` and works in a dock, in a tab of the workflow, and undocked (tests).

    Parameters
    ----------
    viewer : napari.viewer.Viewer
    kind : str
        napari layer class name, e.g. ``"Image"``.
    label : str
        Row label in a magicgui Container.
    accept : callable, optional
        Further filter on layers (e.g. not the 3-D extent overlay).
    none_text : str, optional
        When given, a first entry with this text selects no layer (value None).
    tooltip : str, optional

    Returns
    -------
    magicgui.widgets.ComboBox
        ``.value`` is the selected layer (or None); ``.changed`` is emitted with it.
    """
    import napari.layers
    from magicgui.widgets import ComboBox

    layer_type = getattr(napari.layers, kind)

    def choices(_widget):
        layers = [layer for layer in viewer.layers if isinstance(layer, layer_type)
                  and (accept is None or accept(layer))]
        return ([(none_text, None)] if none_text is not None else []) + \
            [(layer.name, layer) for layer in layers]

    combo = ComboBox(label=label, choices=choices, tooltip=tooltip)
    combo._follower = _Follower(viewer, combo)
    return combo


def pick(combo, layer) -> None:
    """Select `layer` in a :func:`layer_picker` (re-listing first, in case it was just added)."""
    combo.reset_choices()
    if layer in combo.choices:
        combo.value = layer
