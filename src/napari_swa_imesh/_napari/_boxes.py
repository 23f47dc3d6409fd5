"""Sample rectangles drawn in napari <-> sample boxes of the library, and their flags.

Coordinates
-----------
Rectangles are given in the *image layer's data coordinates* (pixel index space): napari
puts the centre of pixel ``i`` at ``i``, so pixel ``i`` spans ``[i - 0.5, i + 0.5)``. A
rectangle is turned into the pixels it covers by rounding each side to the nearest pixel
edge: ``start = floor(lo + 0.5)``, ``stop = floor(hi + 0.5)`` (stop exclusive), and a box
is drawn back as the rectangle from ``start - 0.5`` to ``stop - 0.5``; the round trip is
exact.

In 3-D a rectangle lies on one slice (the axis along which all its corners agree, the
*thickness axis*); its ``depth`` (number of slices, centred on that slice) makes it a box:
``start = slice - depth // 2``, ``stop = start + depth``.

Flags
-----
A shape is never dropped silently: every shape gets a flag string, empty when it is fine.
``not a box`` (not an axis-aligned rectangle on one slice), ``empty`` (thinner than a
pixel), ``outside`` (partly or wholly outside the image) make the samples unusable until
fixed; ``too small at scale j`` (shorter than one 2^j tile along some axis: it gives no
training tile) and ``constant`` (all its pixels equal: padding or saturation, no texture)
are warnings. ``too small for scale j windows (needs N px)`` marks every box of a
material whose *largest* box cannot hold one window of ``N = 2^j + 1`` px per axis: the
recommended method trains scale j on such windows, so that material cannot be trained at
j (see :meth:`Samples.window_scales`); it is a warning too, the library caps the scale.
A box already flagged ``too small at scale j`` (shorter than 2^j) does not get it again:
that flag already says it is too small, and the two would differ only by the one pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..segmentation import Material, SampleBox, Samples

__all__ = ["BoxReport", "rectangles_to_boxes", "box_to_rectangle", "BLOCKING_FLAGS",
           "box_flags", "window_flags", "window_flag"]

#: Flags that make a shape unusable as a sample box (the run is refused until fixed).
BLOCKING_FLAGS = ("not a box", "empty", "outside")


@dataclass
class BoxReport:
    """Boxes made from the shapes of a samples layer, one entry per shape.

    Attributes
    ----------
    boxes : list of SampleBox or None
        The box of each shape (None when the shape is not a box or is empty).
    flags : list of list of str
        Flags of each shape (see the module docstring); empty lists for good boxes.
    thickness_axis : list of int or None
        Per shape, the axis along which its rectangle is flat (3-D), else None.
    """

    boxes: list[SampleBox | None]
    flags: list[list[str]]
    thickness_axis: list[int | None]

    @property
    def blocking(self) -> list[int]:
        """Indices of shapes whose flags make them unusable."""
        return [i for i, f in enumerate(self.flags) if any(b in f for b in BLOCKING_FLAGS)]

    def flag_text(self, i: int) -> str:
        return ", ".join(self.flags[i])


def rectangles_to_boxes(rectangles, labels, depths, image_shape, *, scale: int | None = None,
                        shape_types=None) -> BoxReport:
    """Pixel boxes of rectangles given in image data coordinates, with flags.

    Parameters
    ----------
    rectangles : sequence of (4, d) array_like of float
        Corners of each rectangle in the image's data (pixel index) coordinates.
    labels : sequence of int
        Material label of each rectangle.
    depths : sequence of int
        Number of slices of each box along its thickness axis (3-D only; ignored in 2-D).
    image_shape : tuple of int
        Shape of the image the boxes sample.
    scale : int, optional
        Tile scale j at which to flag boxes too small to hold a tile.
    shape_types : sequence of str, optional
        napari shape type of each shape; anything but ``"rectangle"`` is flagged.

    Returns
    -------
    BoxReport

    Examples
    --------
    >>> r = rectangles_to_boxes([[[-0.5, -0.5], [-0.5, 7.5], [7.5, 7.5], [7.5, -0.5]]],
    ...                         [1], [1], (16, 16), scale=3)
    >>> r.boxes[0].start, r.boxes[0].stop, r.flags[0]
    ((0, 0), (8, 8), [])
    """
    d = len(image_shape)
    shape_arr = np.asarray(image_shape)
    boxes: list[SampleBox | None] = []
    flags: list[list[str]] = []
    axes: list[int | None] = []
    for i, (rect, label, depth) in enumerate(zip(rectangles, labels, depths)):
        corners = np.asarray(rect, dtype=float)
        kind = None if shape_types is None else shape_types[i]
        if corners.ndim != 2 or corners.shape[1] != d or (kind not in (None, "rectangle")):
            boxes.append(None), flags.append(["not a box"]), axes.append(None)
            continue
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        start = np.floor(lo + 0.5).astype(int)
        stop = np.floor(hi + 0.5).astype(int)
        flat = np.flatnonzero(hi - lo < 1e-6)
        axis = None
        if d == 3:
            if flat.size != 1:
                boxes.append(None), flags.append(["not a box"]), axes.append(None)
                continue
            axis = int(flat[0])
            depth = max(int(depth), 1)
            start[axis] = int(np.floor(lo[axis] + 0.5)) - depth // 2
            stop[axis] = start[axis] + depth
        axes.append(axis)
        if (stop <= start).any():
            boxes.append(None), flags.append(["empty"])
            continue
        box = SampleBox(int(label), tuple(int(v) for v in start), tuple(int(v) for v in stop))
        boxes.append(box)
        shape_flags = []
        if (start < 0).any() or (stop > shape_arr).any():
            shape_flags.append("outside")
        if scale is not None and min(box.shape) < (1 << scale):
            shape_flags.append(f"too small at scale {scale}")
        flags.append(shape_flags)
    return BoxReport(boxes, flags, axes)


def box_flags(report: BoxReport, image: np.ndarray) -> BoxReport:
    """Add the ``constant`` flag to boxes inside `image` whose pixels are all equal."""
    for box, shape_flags in zip(report.boxes, report.flags):
        if box is None or "outside" in shape_flags:
            continue
        crop = np.asarray(image[box.slices])
        if crop.size and crop.min() == crop.max():
            shape_flags.append("constant")
    return report


def window_flag(scale: int) -> str:
    """Flag text of a box whose material cannot hold a scale-`scale` window."""
    return f"too small for scale {scale} windows (needs {(1 << scale) + 1} px)"


def window_flags(report: BoxReport, scale: int | None) -> BoxReport:
    """Flag the boxes of a material whose largest box holds no window at `scale`.

    Boxes already flagged ``too small at scale j`` are left as they are.

    Uses :meth:`Samples.window_scales` on the usable boxes of `report`, so the GUI flags
    exactly the materials the library will refuse to train at `scale`.

    Examples
    --------
    >>> r = BoxReport([SampleBox(1, (0, 0), (32, 32)), SampleBox(2, (0, 0), (8, 40))],
    ...               [[], []], [None, None])
    >>> window_flags(r, 3).flags
    [[], ['too small for scale 3 windows (needs 9 px)']]
    """
    if scale is None:
        return report
    usable = [i for i, box in enumerate(report.boxes)
              if box is not None and i not in report.blocking]
    labels = sorted({report.boxes[i].label for i in usable})
    samples = Samples([Material(label, str(label)) for label in labels],
                      [report.boxes[i] for i in usable])
    short = {label for label, j in samples.window_scales().items() if j < scale}
    tile_flag = f"too small at scale {scale}"
    for i in usable:
        if report.boxes[i].label in short and tile_flag not in report.flags[i]:
            report.flags[i].append(window_flag(scale))
    return report


def box_to_rectangle(box: SampleBox, *, thickness_axis: int = 0) -> tuple[np.ndarray, int]:
    """The rectangle (image data coordinates) that draws `box`, and its depth.

    In 3-D the rectangle lies on the box's middle slice along `thickness_axis`
    (``start + depth // 2``, the inverse of :func:`rectangles_to_boxes`).

    Returns
    -------
    corners : (4, d) ndarray of float
    depth : int
        Slices along the thickness axis (1 in 2-D).

    Examples
    --------
    >>> corners, depth = box_to_rectangle(SampleBox(1, (0, 0), (8, 4)))
    >>> corners.tolist(), depth
    ([[-0.5, -0.5], [-0.5, 3.5], [7.5, 3.5], [7.5, -0.5]], 1)
    """
    start = np.asarray(box.start, dtype=float)
    stop = np.asarray(box.stop, dtype=float)
    d = start.size
    if d == 2:
        in_plane, depth = (0, 1), 1
    else:
        in_plane = tuple(a for a in range(d) if a != thickness_axis)
        depth = int(stop[thickness_axis] - start[thickness_axis])
    a, b = in_plane
    corners = np.empty((4, d))
    if d == 3:
        corners[:, thickness_axis] = start[thickness_axis] + depth // 2
    lo, hi = start - 0.5, stop - 0.5
    corners[:, a] = [lo[a], lo[a], hi[a], hi[a]]
    corners[:, b] = [lo[b], hi[b], hi[b], lo[b]]
    return corners, depth
