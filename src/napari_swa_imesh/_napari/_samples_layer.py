"""The samples Shapes layer: rectangles with a material per shape, read as library Samples.

A samples layer is a napari Shapes layer with the image's scale and translate, whose
features hold, per shape, the material ``label`` and ``name``, the ``depth`` in slices
(3-D) and the ``flag`` text (see :mod:`._boxes`). Its metadata holds the material table
(label, name, colour), the name of the image it samples, and the scale chosen from the RES
plots, so every widget can rebuild the library's :class:`Samples` from the layers alone.

The chosen scale is stored with the fingerprint (:func:`samples_fingerprint`) of the boxes,
materials and image pixels its RES statistics were computed from. A choice whose
fingerprint no longer matches the layers is *stale*: :func:`chosen_scale` then returns
None, so no consumer can reuse a scale chosen on other boxes by accident.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..segmentation import Material, Samples
from ._boxes import BoxReport, box_flags, box_to_rectangle, rectangles_to_boxes, window_flags
from ._layers import (
    EXTENT_KEY,
    MATERIALS_KEY,
    SAMPLES_KEY,
    SCALE_KEY,
    default_color,
    index_to_layer_data,
    is_layer,
)

if TYPE_CHECKING:
    import napari

__all__ = ["new_samples_layer", "layer_materials", "set_layer_materials", "layer_report",
           "samples_from_layer", "put_boxes", "restyle", "update_extent_overlay",
           "is_samples_layer", "is_extent_layer", "image_array", "DEFAULT_DEPTH",
           "samples_fingerprint", "ScaleChoice", "scale_choice", "store_chosen_scale",
           "chosen_scale", "SamplesWatcher", "report_window_limit"]

DEFAULT_DEPTH = 8
_EDGE_WIDTH_PX = 1.5  # in screen-ish units: edge widths are scaled by the layer scale


def is_extent_layer(layer) -> bool:
    return EXTENT_KEY in layer.metadata


def is_samples_layer(layer) -> bool:
    """Any Shapes layer but the 3-D extent overlay can hold samples."""
    return is_layer(layer, "Shapes") and not is_extent_layer(layer)


def image_array(image_layer) -> np.ndarray:
    """The image layer's pixels as one grey-level array (level 0 of a multiscale image)."""
    if image_layer.rgb:
        raise ValueError(
            f"image layer {image_layer.name!r} is RGB; SWA needs one grey-level channel. "
            "Split the channels (right-click the layer > Split RGB) and pick one.")
    data = image_layer.data[0] if image_layer.multiscale else image_layer.data
    return np.asarray(data)


def _empty_features() -> pd.DataFrame:
    return pd.DataFrame({"label": pd.Series([], dtype=int), "name": pd.Series([], dtype=object),
                         "depth": pd.Series([], dtype=int), "flag": pd.Series([], dtype=object)})


def new_samples_layer(viewer: napari.viewer.Viewer, image_layer, materials: list[Material],
                      *, name: str | None = None, depth: int = DEFAULT_DEPTH):
    """Add an empty samples Shapes layer over `image_layer`, ready to draw rectangles."""
    layer = viewer.add_shapes(
        ndim=image_layer.ndim, scale=image_layer.scale, translate=image_layer.translate,
        name=name or f"{image_layer.name} samples", face_color="transparent",
        edge_width=_EDGE_WIDTH_PX, features=_empty_features(),
        text={"string": "{name}{flag}", "color": "white", "size": 9, "anchor": "upper_left"},
        metadata={SAMPLES_KEY: image_layer.name, MATERIALS_KEY: _material_table(materials)})
    set_layer_materials(layer, materials)
    set_current_material(layer, materials[0] if materials else Material(1, "material 1"),
                         depth=depth if image_layer.ndim == 3 else 1)
    return layer


def adopt_layer(layer, material: Material, *, depth: int = 1) -> None:
    """Make any Shapes layer a samples layer: every shape without a material gets `material`.

    Lets a user start from rectangles drawn before the plugin was opened.
    """
    n = len(layer.data)
    features = layer.features.copy() if len(layer.features) == n else pd.DataFrame(index=range(n))
    if "label" not in features:
        features["label"] = material.label
        features["name"] = material.name
    if "depth" not in features:
        features["depth"] = depth
    if "flag" not in features:
        features["flag"] = ""
    layer.features = features
    if MATERIALS_KEY not in layer.metadata:
        set_layer_materials(layer, [material])
    set_current_material(layer, material, depth=depth)
    layer.text = {"string": "{name}{flag}", "color": "white", "size": 9, "anchor": "upper_left"}


def layer_materials(layer) -> list[Material]:
    """Materials of a samples layer: its table, plus any label used by a shape but unlisted."""
    table = [Material(int(m["label"]), str(m["name"]), m.get("color"))
             for m in layer.metadata.get(MATERIALS_KEY, [])]
    known = {m.label for m in table}
    if "label" in layer.features and len(layer.features):
        names = layer.features.get("name")
        for i, label in enumerate(layer.features["label"].astype(int)):
            if label not in known:
                name = str(names.iloc[i]) if names is not None else f"material {label}"
                table.append(Material(int(label), name, None))
                known.add(int(label))
    return table


def _material_table(materials: list[Material]) -> list[dict]:
    return [{"label": m.label, "name": m.name, "color": m.color or default_color(m.label)}
            for m in materials]


def set_layer_materials(layer, materials: list[Material]) -> None:
    """Store the material table in the layer and rename/recolour its shapes to match."""
    layer.metadata[MATERIALS_KEY] = _material_table(materials)
    if len(layer.data) and "label" in layer.features:
        names = {m.label: m.name for m in materials}
        features = layer.features.copy()
        features["name"] = [names.get(int(v), f"material {int(v)}") for v in features["label"]]
        layer.features = features
    _recolor(layer)


def set_current_material(layer, material: Material, *, depth: int | None = None) -> None:
    """Material (and depth) that newly drawn rectangles get."""
    defaults = {"label": material.label, "name": material.name, "flag": ""}
    defaults["depth"] = int(depth) if depth is not None else int(
        layer.feature_defaults["depth"].iloc[0] if "depth" in layer.feature_defaults else 1)
    layer.feature_defaults = defaults
    layer.current_edge_color = material.color or default_color(material.label)
    _recolor(layer)


def _colors(layer) -> dict[int, str]:
    return {int(m["label"]): m.get("color") or default_color(m["label"])
            for m in layer.metadata.get(MATERIALS_KEY, [])}


def _recolor(layer) -> None:
    """Edge colour of every shape from its material (the only place colours are set)."""
    if not len(layer.data) or "label" not in layer.features:
        return
    colors = _colors(layer)
    layer.edge_color = [colors.get(int(v), default_color(int(v))) for v in layer.features["label"]]


def _raw_report(layer, image_layer, image: np.ndarray, scale: int | None) -> BoxReport:
    features = layer.features
    n = len(layer.data)
    labels = features["label"].astype(int).tolist() if "label" in features else [1] * n
    depths = features["depth"].astype(int).tolist() if "depth" in features else [1] * n
    corners = [index_to_layer_data(v, layer, image_layer) for v in layer.data]
    return rectangles_to_boxes(corners, labels, depths, image.shape, scale=scale,
                               shape_types=list(layer.shape_type))


def layer_report(layer, image_layer, *, scale: int | None = None) -> BoxReport:
    """Boxes (image pixel indices) and flags of every shape of a samples layer.

    With a `scale`, boxes too small for a tile and materials too small for a window at
    that scale are flagged (see :mod:`._boxes`).
    """
    image = image_array(image_layer)
    report = box_flags(_raw_report(layer, image_layer, image, scale), image)
    return window_flags(report, scale)


def samples_fingerprint(layer, image_layer) -> str:
    """Digest of everything a RES of these samples depends on.

    The image layer's name, shape and dtype; per shape its material label and pixel box
    (order included); the material table (labels and names, which the plots show); and
    the image pixels inside every box, so editing the image under a box counts too.
    Flags, colours and depth defaults are left out: they change no statistic.

    Returns
    -------
    str
        32 hex digits; equal for equal inputs, different (in practice) otherwise.
    """
    image = image_array(image_layer)
    digest = hashlib.blake2b(digest_size=16)
    digest.update(repr((image_layer.name, image.shape, str(image.dtype))).encode())
    materials = sorted((m.label, m.name) for m in layer_materials(layer))
    digest.update(repr(materials).encode())
    shape = np.asarray(image.shape)
    for box in _raw_report(layer, image_layer, image, None).boxes:
        if box is None:
            digest.update(b"none;")
            continue
        digest.update(repr((box.label, box.start, box.stop)).encode())
        lo = np.clip(box.start, 0, shape)
        hi = np.clip(box.stop, 0, shape)
        crop = np.ascontiguousarray(image[tuple(slice(a, b) for a, b in zip(lo, hi))])
        digest.update(crop.tobytes())
    return digest.hexdigest()


def report_window_limit(layer, report: BoxReport, scale: int | None
                        ) -> tuple[int, str] | None:
    """:meth:`Samples.window_limit` of the boxes of `report` at `scale` (None if fine).

    None too when some shape is not yet a usable box: the blocking flags come first.
    """
    if scale is None or report.blocking or not any(b is not None for b in report.boxes):
        return None
    used = {b.label for b in report.boxes}
    materials = [m for m in layer_materials(layer) if m.label in used]
    return Samples(materials, list(report.boxes)).window_limit(int(scale))


def _shape_name(layer, i: int) -> str:
    if "name" in layer.features and i < len(layer.features):
        return f"box {i + 1} ({layer.features['name'].iloc[i]})"
    return f"box {i + 1}"


def samples_from_layer(layer, image_layer, *, scale: int | None = None
                       ) -> tuple[Samples, BoxReport]:
    """Library Samples from a samples layer, refusing shapes that cannot be boxes.

    Raises
    ------
    ValueError
        No shapes, or a shape flagged ``not a box``, ``empty`` or ``outside``; the message
        says which shape and what to do.
    """
    if not len(layer.data):
        raise ValueError(f"the samples layer {layer.name!r} has no boxes; draw at least one "
                         "rectangle per material (rectangle tool) or import a samples file.")
    if "label" not in layer.features:
        raise ValueError(f"the Shapes layer {layer.name!r} gives no material per box; pick it "
                         "in the samples widget, which assigns materials to its rectangles.")
    report = layer_report(layer, image_layer, scale=scale)
    for i in report.blocking:
        what = _shape_name(layer, i)
        if "outside" in report.flags[i]:
            box = report.boxes[i]
            raise ValueError(
                f"{what} from {list(box.start)} to {list(box.stop)} lies partly outside the "
                f"image of shape {image_array(image_layer).shape}; move it inside the image "
                "or delete it.")
        if "empty" in report.flags[i]:
            raise ValueError(f"{what} is thinner than one pixel; redraw it larger or delete it.")
        raise ValueError(f"{what} is not an axis-aligned rectangle on one slice; draw sample "
                         "boxes with the rectangle tool in 2-D view, or delete it.")
    used = {b.label for b in report.boxes}
    materials = [m for m in layer_materials(layer) if m.label in used]
    return Samples(materials, list(report.boxes)), report


def put_boxes(layer, image_layer, samples: Samples, *, thickness_axis: int = 0) -> None:
    """Replace the shapes of a samples layer by rectangles drawing `samples`' boxes."""
    rects, depths = [], []
    for box in samples.boxes:
        corners, depth = box_to_rectangle(box, thickness_axis=thickness_axis)
        rects.append(index_to_layer_data(corners, image_layer, layer))
        depths.append(depth)
    names = {m.label: m.name for m in samples.materials}
    set_layer_materials(layer, samples.materials)
    layer.selected_data = set()
    layer.data = []
    if not rects:
        return
    defaults = layer.feature_defaults
    features = pd.DataFrame({
        "label": [b.label for b in samples.boxes],
        "name": [names.get(b.label, f"material {b.label}") for b in samples.boxes],
        "depth": depths, "flag": [""] * len(rects)})
    layer.add_rectangles(rects)
    layer.features = features
    layer.feature_defaults = defaults
    _recolor(layer)


def restyle(layer, report: BoxReport) -> None:
    """Show each shape's flags as its text and colour it by material."""
    if not len(layer.data):
        return
    features = layer.features.copy()
    features["flag"] = [f"  ! {report.flag_text(i)}" if report.flags[i] else ""
                        for i in range(len(report.flags))]
    if "depth" not in features:
        features["depth"] = 1
    layer.features = features
    layer.refresh_text()
    _recolor(layer)


def update_extent_overlay(viewer: napari.viewer.Viewer, layer, image_layer,
                          report: BoxReport):
    """Draw each 3-D box's extent on its neighbouring slices (a read-only Shapes layer).

    napari shows a rectangle only on its own slice; this overlay holds a copy of it on
    every other slice the box covers, so the box is visible wherever it samples.
    Returns the overlay layer (None in 2-D).
    """
    if layer.ndim != 3:
        return None
    rects, colors = [], []
    color_of = _colors(layer)
    for box, axis in zip(report.boxes, report.thickness_axis):
        if box is None or axis is None:
            continue
        corners, _ = box_to_rectangle(box, thickness_axis=axis)
        own = corners[0, axis]
        planes = np.arange(box.start[axis], box.stop[axis])
        planes = planes[planes != own]
        copies = np.repeat(corners[None], len(planes), axis=0)    # (P, 4, 3)
        copies[:, :, axis] = planes[:, None]
        rects.extend(index_to_layer_data(c, image_layer, layer) for c in copies)
        colors.extend([color_of.get(box.label, default_color(box.label))] * len(planes))
    overlay = next((lay for lay in viewer.layers
                    if lay.metadata.get(EXTENT_KEY) == layer.name), None)
    if overlay is None:
        active = viewer.layers.selection.active
        overlay = viewer.add_shapes(
            ndim=3, scale=layer.scale, translate=layer.translate, name=f"{layer.name} extent",
            face_color="transparent", edge_width=_EDGE_WIDTH_PX / 2, opacity=0.6,
            metadata={EXTENT_KEY: layer.name})
        overlay.editable = False
        if active is not None:
            viewer.layers.selection.active = active
    overlay.data = []
    if rects:
        overlay.add_rectangles(rects, edge_color=colors)
    return overlay


@dataclass(frozen=True)
class ScaleChoice:
    """A scale chosen from the RES plots and whether it still fits the samples.

    Attributes
    ----------
    scale : int
        The chosen scale j.
    fresh : bool
        True when the boxes, materials and image are those the RES was computed from.
    suggested : int or None
        The suggested RES of the statistics the choice was made on.
    """

    scale: int
    fresh: bool
    suggested: int | None = None


def store_chosen_scale(layer, scale: int, *, fingerprint: str,
                       suggested: int | None = None) -> None:
    """Store `scale` as chosen on samples with `fingerprint` (that of the RES statistics)."""
    layer.metadata[SCALE_KEY] = {"scale": int(scale), "fingerprint": str(fingerprint),
                                 "suggested": None if suggested is None else int(suggested)}


def scale_choice(layer, image_layer) -> ScaleChoice | None:
    """The stored scale choice of a samples layer, checked against the layers now.

    A choice stored without a fingerprint (an older plugin) counts as stale: nothing
    says which boxes it was chosen on.
    """
    value = layer.metadata.get(SCALE_KEY)
    if value is None:
        return None
    if not isinstance(value, dict):
        return ScaleChoice(int(value), False)
    fresh = False
    if image_layer is not None:
        try:
            fresh = value.get("fingerprint") == samples_fingerprint(layer, image_layer)
        except ValueError:           # an RGB image: nothing can be fresh on it
            fresh = False
    suggested = value.get("suggested")
    return ScaleChoice(int(value["scale"]), fresh, None if suggested is None else int(suggested))


def chosen_scale(layer, image_layer) -> int | None:
    """The scale chosen from the RES plots for exactly these samples and image, else None.

    None also when a scale was chosen on other boxes, materials or image (a stale choice,
    see :func:`scale_choice`).
    """
    choice = scale_choice(layer, image_layer)
    return choice.scale if choice is not None and choice.fresh else None


class SamplesWatcher:
    """Call `callback()` whenever a samples layer or its image changes in a way that can
    change the samples: shapes added, removed or moved (final data events only), their
    features edited (material, depth), the image's pixels replaced.

    Listens to napari's layer events (``events.data``, ``events.features``); call
    :meth:`watch` with the layers in use (None to stop).
    """

    def __init__(self, callback):
        self.callback = callback
        self.layer = None
        self.image_layer = None

    def watch(self, layer, image_layer) -> None:
        if layer is not self.layer:
            if self.layer is not None:
                self.layer.events.data.disconnect(self._on_data)
                self.layer.events.features.disconnect(self._on_event)
            if layer is not None:
                layer.events.data.connect(self._on_data)
                layer.events.features.connect(self._on_event)
            self.layer = layer
        if image_layer is not self.image_layer:
            if self.image_layer is not None:
                self.image_layer.events.data.disconnect(self._on_event)
            if image_layer is not None:
                image_layer.events.data.connect(self._on_event)
            self.image_layer = image_layer

    def _on_data(self, event=None) -> None:
        action = str(getattr(event, "action", "")) if event is not None else ""
        if action.endswith("ing"):      # adding/changing/removing: wait for the final event
            return
        self._on_event(event)

    def _on_event(self, event=None) -> None:
        try:
            self.callback()
        except RuntimeError:            # the widget's Qt side is gone: stop listening
            self.watch(None, None)
