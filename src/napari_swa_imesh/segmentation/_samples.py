"""Sample boxes per material: the JSON file format, checks, and samples from a truth image.

JSON schema (array index order; ``start`` inclusive, ``stop`` exclusive; one entry per
image axis)::

    {"materials": [{"label": 1, "name": "brick", "color": "#d62728"}, ...],
     "boxes": [{"label": 1, "start": [r0, c0], "stop": [r1, c1]}, ...]}

``color`` is optional. Unknown keys are ignored with a warning that names them.
"""

from __future__ import annotations

import json
import numbers
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._region_tree import build_tree
from .._validation import IMAGE_NDIM, as_labels

__all__ = ["Material", "SampleBox", "Samples", "load_samples", "save_samples",
           "samples_from_truth", "window_scale", "check_contrast", "check_box_contrast",
           "BoxCrops"]


@dataclass(frozen=True)
class Material:
    """A material (class): its label id in the output, a name, an optional colour.

    Parameters
    ----------
    label : int
        Label of the material in the output image (1, 2, ...; 0 is background).
    name : str
        Its name, as files and tables show it.
    color : str or None
        A colour for drawing (any matplotlib colour string), or None.
    """

    label: int
    name: str
    color: str | None = None


@dataclass(frozen=True)
class SampleBox:
    """An axis-aligned box of pixels known to hold one material (stop exclusive).

    Parameters
    ----------
    label : int
        The material's label.
    start : tuple of int
        First pixel index per axis, (plane, row, column) order, inclusive.
    stop : tuple of int
        Last pixel index + 1 per axis (exclusive).
    """

    label: int
    start: tuple[int, ...]
    stop: tuple[int, ...]

    @property
    def slices(self) -> tuple[slice, ...]:
        return tuple(slice(a, b) for a, b in zip(self.start, self.stop))

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(b - a for a, b in zip(self.start, self.stop))


@dataclass
class Samples:
    """Materials and their sample boxes.

    Parameters
    ----------
    materials : list of Material
        Every material, each label once.
    boxes : list of SampleBox
        The boxes; each box's label is one of the materials'.

    Examples
    --------
    >>> s = Samples.from_dict({"materials": [{"label": 1, "name": "a"}],
    ...                        "boxes": [{"label": 1, "start": [0, 0], "stop": [8, 8]}]})
    >>> s.boxes[0].shape
    (8, 8)
    """

    materials: list[Material] = field(default_factory=list)
    boxes: list[SampleBox] = field(default_factory=list)

    @property
    def labels(self) -> list[int]:
        """Material labels in the order materials are listed."""
        return [m.label for m in self.materials]

    def name_of(self, label: int) -> str:
        for m in self.materials:
            if m.label == label:
                return m.name
        return f"material {label}"

    def boxes_of(self, label: int) -> list[SampleBox]:
        return [b for b in self.boxes if b.label == label]

    def window_scales(self) -> dict[int, int]:
        """Per material: the largest scale j whose window (2^j + 1 px per axis) fits
        inside one of its boxes (:func:`window_scale` of its largest box).

        The recommended method trains level j on windows of that size, so a material can
        only be trained up to this scale; the smallest value over materials caps every
        level.

        Examples
        --------
        >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [64, 80]},
        ...                                  {"label": 2, "start": [0, 0], "stop": [9, 9]}]})
        >>> s.window_scales()
        {1: 5, 2: 3}
        """
        return {m.label: max((window_scale(b.shape) for b in self.boxes_of(m.label)),
                             default=-1) for m in self.materials}

    def tile_counts(self, scale: int) -> dict[int, int]:
        """Per material: full tiles of 2^scale px in its boxes (aligned to each box's corner).

        Examples
        --------
        >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [8, 12]}]})
        >>> s.tile_counts(2)
        {1: 6}
        """
        return {m.label: sum(int(np.prod([n >> scale for n in b.shape]))
                             for b in self.boxes_of(m.label)) for m in self.materials}

    def tile_limit(self, scale: int, need: int) -> tuple[int, str] | None:
        """If some material has fewer than `need` full tiles at `scale`, the largest scale
        where every material has them (-1: none) and a sentence naming the box to enlarge;
        else None."""
        counts = self.tile_counts(scale)
        short = [m for m in counts if counts[m] < need]
        if not short:
            return None
        usable = next((j for j in range(scale - 1, -1, -1)
                       if min(self.tile_counts(j).values()) >= need), -1)
        worst = min(short, key=lambda m: counts[m])
        biggest = max(self.boxes_of(worst), key=lambda b: int(np.prod(b.shape)))
        return usable, (
            f"at scale {scale} the boxes of {self.name_of(worst)!r} (label {worst}) hold "
            f"{counts[worst]} full tile(s) of {1 << scale} px, fewer than the {need} the "
            f"classifier needs; enlarge its box #{self.boxes.index(biggest)} or add boxes"
            + (f", or use scale {usable} or less" if usable >= 0 else ""))

    def window_limit(self, scale: int) -> tuple[int, str] | None:
        """If some material cannot be trained at `scale`, the scale every material can be
        trained at and a sentence that says which box to enlarge; else None."""
        scales = self.window_scales()
        worst = min(scales, key=lambda m: scales[m])
        if scales[worst] >= scale:
            return None
        side = (1 << scale) + 1
        biggest = max(self.boxes_of(worst), key=lambda b: min(b.shape))
        index = self.boxes.index(biggest)
        shape = "x".join(map(str, biggest.shape))
        return scales[worst], (
            f"scale {scale} needs windows of {side} px inside a box of every material, but "
            f"the largest box of {self.name_of(worst)!r} (box #{index}, label {worst}) is "
            f"{shape} px; enlarge it to at least {side} px per axis, or use scale "
            f"{scales[worst]} or less")

    @classmethod
    def from_dict(cls, data: dict) -> Samples:
        """Build from the JSON structure, checking it says what the schema says.

        Labels and coordinates must be whole numbers (``1`` or ``1.0``, never ``1.5`` or
        ``true``); keys the schema does not know are reported in a warning that names
        them (a misspelled key would otherwise be ignored).
        """
        if not isinstance(data, dict) or not isinstance(data.get("boxes"), list):
            raise ValueError(
                "samples must be a JSON object with a 'boxes' list (and a 'materials' list); "
                "see the README for the schema."
            )
        _warn_unknown(data, {"materials", "boxes"}, "the samples")
        if not isinstance(data.get("materials", []), list):
            raise ValueError("'materials' in the samples must be a list of objects with "
                             "'label' and 'name'; see the README for the schema.")
        materials = []
        for i, m in enumerate(data.get("materials", [])):
            if not isinstance(m, dict) or "label" not in m:
                raise ValueError(f"material #{i} needs an integer 'label'; got {m!r}.")
            _warn_unknown(m, {"label", "name", "color"}, f"material #{i}")
            label = _whole(m["label"], f"material #{i}'s label")
            name = m.get("name", f"material {label}")
            color = m.get("color")
            if not isinstance(name, str) or (color is not None and not isinstance(color, str)):
                raise ValueError(f"material #{i}: 'name' and 'color' must be text; got {m!r}.")
            materials.append(Material(label, name, color))
        boxes = []
        for i, b in enumerate(data["boxes"]):
            if not isinstance(b, dict) or not all(k in b for k in ("label", "start", "stop")) \
                    or not all(isinstance(b[k], list) for k in ("start", "stop")):
                raise ValueError(
                    f"box #{i} needs 'label', 'start' and 'stop' (integer lists); got {b!r}.")
            _warn_unknown(b, {"label", "start", "stop"}, f"box #{i}")
            label = _whole(b["label"], f"box #{i}'s label")
            start = tuple(_whole(v, f"box #{i}'s start") for v in b["start"])
            stop = tuple(_whole(v, f"box #{i}'s stop") for v in b["stop"])
            if len(start) != len(stop):
                raise ValueError(f"box #{i}: start {list(start)} and stop {list(stop)} differ "
                                 "in length.")
            if any(b1 <= a for a, b1 in zip(start, stop)):
                raise ValueError(
                    f"box #{i} is empty: stop {list(stop)} must exceed start {list(start)} on "
                    "every axis (stop is exclusive)."
                )
            boxes.append(SampleBox(label, start, stop))
        known = {m.label for m in materials}
        for b in boxes:
            if b.label not in known:
                materials.append(Material(b.label, f"material {b.label}"))
                known.add(b.label)
        if len({m.label for m in materials}) != len(materials):
            raise ValueError("samples list the same material label twice; give each label once.")
        for m in materials:
            if not 0 < m.label < 1 << 63:
                raise ValueError(
                    f"material label {m.label} is not allowed: 0 is background in napari "
                    "Labels, so materials are 1, 2, ... up to 2^63 - 1; renumber it."
                )
        return cls(materials, boxes)

    def to_dict(self) -> dict:
        mats = []
        for m in self.materials:
            entry = {"label": m.label, "name": m.name}
            if m.color:
                entry["color"] = m.color
            mats.append(entry)
        return {"materials": mats,
                "boxes": [{"label": b.label, "start": list(b.start), "stop": list(b.stop)}
                          for b in self.boxes]}

    def check(self, shape: tuple[int, ...]) -> None:
        """Raise ValueError unless every box lies inside an image of `shape`."""
        if not self.boxes:
            raise ValueError("no sample boxes given; draw at least one box per material.")
        for i, b in enumerate(self.boxes):
            if len(b.start) != len(shape):
                raise ValueError(
                    f"box #{i} (label {b.label}) has {len(b.start)} axes but the image has "
                    f"{len(shape)} (shape {shape}); give start/stop for every axis."
                )
            if any(a < 0 for a in b.start) or any(s > n for s, n in zip(b.stop, shape)):
                raise ValueError(
                    f"box #{i} (label {b.label}) from {list(b.start)} to {list(b.stop)} lies "
                    f"(partly) outside the image of shape {shape}; move or shrink it."
                )
        missing = [m.label for m in self.materials if not self.boxes_of(m.label)]
        if missing:
            raise ValueError(
                f"material(s) {missing} have no sample box; draw a box for each or remove them."
            )


def _whole(value, what: str) -> int:
    """`value` as an int when it is a whole number (not a bool, fraction or infinity)."""
    if not isinstance(value, (bool, np.bool_)):
        if isinstance(value, numbers.Integral):
            return int(value)
        if isinstance(value, numbers.Real):
            number = float(value)
            if np.isfinite(number) and number.is_integer():
                return int(number)
    shown = json.dumps(value) if isinstance(value, (bool, int, float, str)) else value
    raise ValueError(f"{what} must be a whole number; got {shown}. Give "
                     "pixel indices and labels as integers.")


def _warn_unknown(entry: dict, known: set[str], where: str) -> None:
    unknown = sorted(set(entry) - known)
    if unknown:
        warnings.warn(f"{where} hold unknown key(s) {', '.join(map(repr, unknown))}, which "
                      f"are ignored; the known keys are {', '.join(sorted(known))}.",
                      UserWarning, stacklevel=3)


def check_contrast(image: np.ndarray, samples: Samples | None = None) -> None:
    """Refuse an image with nothing to segment: one value everywhere, or (with `samples`)
    sample boxes that all hold one and the same value.

    Raises
    ------
    ValueError
        With a sentence that says what to do.
    """
    lo, hi = float(image.min()), float(image.max())
    if lo == hi:
        raise ValueError(
            f"the image holds one value everywhere ({lo:g}); there is nothing to segment. "
            "Check that the right file or channel was given.")
    if samples is not None:
        check_box_contrast([image[b.slices] for b in samples.boxes])


class BoxCrops:
    """Reads inside the sample boxes from the boxes' own crops, as the whole image would
    give them: what needs only the boxes (a fit on a store, RES statistics of a large
    image) holds no whole image and reads each box once."""

    def __init__(self, crops: list[np.ndarray], boxes) -> None:
        self.crops, self.boxes = crops, list(boxes)
        self.ndim = crops[0].ndim if crops else 0

    def __getitem__(self, index: tuple) -> np.ndarray:
        for crop, box in zip(self.crops, self.boxes):
            if all(lo <= sl.start and sl.stop <= hi
                   for sl, lo, hi in zip(index, box.start, box.stop)):
                return crop[tuple(slice(sl.start - lo, sl.stop - lo)
                                  for sl, lo in zip(index, box.start))]
        raise IndexError(f"{index} lies in no sample box")


def check_box_contrast(crops) -> None:
    """Refuse sample boxes (their pixels, one array per box) that all hold one value."""
    values = {float(c.min()) for c in crops} | {float(c.max()) for c in crops}
    if len(values) == 1:
        raise ValueError(
            f"every sample box holds the one value {values.pop():g}, so the materials cannot "
            "be told apart; draw the boxes on the materials' own pixels.")


def window_scale(shape) -> int:
    """Largest scale j with a window of 2^j + 1 px inside a box of `shape` (0 for any box).

    Examples
    --------
    >>> [window_scale((n, 100)) for n in (1, 2, 3, 8, 9, 65)]
    [0, 0, 1, 2, 3, 6]
    """
    side = min(int(n) for n in shape)
    return max(0, (side - 1).bit_length() - 1) if side > 1 else 0


def load_samples(path) -> Samples:
    """Read a samples JSON file (see the module docstring for the schema).

    Parameters
    ----------
    path : str or Path
        The JSON file.

    Returns
    -------
    Samples
        Its materials and boxes, checked.

    Raises
    ------
    FileNotFoundError
        No file at `path`.
    ValueError
        The file is not valid JSON, or not a samples file.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no samples file at {p}; check the path.")
    try:
        data = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{p} is not valid JSON: {exc}") from exc
    return Samples.from_dict(data)


def save_samples(samples: Samples, path, *, force: bool = False) -> Path:
    """Write `samples` as JSON; an existing file is replaced only with ``force``.

    Parameters
    ----------
    samples : Samples
        What to write.
    path : str or Path
        The JSON file (written atomically: whole or not at all).
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        `path`.
    """
    from ..io import atomic_write

    with atomic_write([path], force=force) as (tmp,):
        tmp.write_text(json.dumps(samples.to_dict(), indent=2))
    return Path(path)


def samples_from_truth(
    truth, *, scale: int | None = None, per_material: int = 4,
    names: dict[int, str] | None = None,
) -> Samples:
    """Sample boxes from a ground-truth label image: its largest homogeneous blocks.

    The region 2^d-tree of `truth` (the same tree the mesher uses) gives maximal
    homogeneous blocks; the `per_material` largest of each material become boxes.

    Parameters
    ----------
    truth : (M, N[, P]) array_like of int
        Ground truth; 0 is background and gives no samples.
    scale : int, optional
        Tile scale the samples are meant for. Blocks smaller than ``2**(scale+1)`` per
        axis (fewer than 2^d tiles) are skipped while larger ones exist.
    per_material : int
        Number of boxes per material.
    names : dict of int to str, optional
        Material names.

    Returns
    -------
    Samples

    Examples
    --------
    >>> t = np.zeros((8, 8), int); t[:, 4:] = 1; t[:, :4] = 2
    >>> s = samples_from_truth(t, per_material=1)
    >>> [(b.label, b.start, b.stop) for b in s.boxes]
    [(1, (0, 4), (4, 8)), (2, (0, 0), (4, 4))]
    """
    lab = as_labels(truth, name="truth", min_ndim=IMAGE_NDIM[0], max_ndim=IMAGE_NDIM[-1])
    if per_material < 1:
        raise ValueError(f"per_material must be at least 1; got {per_material}.")
    tree = build_tree(lab)
    keep = tree.inside & (tree.label > 0)
    tree = tree.select(keep)
    materials, boxes = [], []
    for label in np.unique(tree.label):
        sel = np.flatnonzero(tree.label == label)
        lev = tree.level[sel]
        if scale is not None and (lev >= scale + 1).any():
            sel, lev = sel[lev >= scale + 1], lev[lev >= scale + 1]
        # largest first; ties broken by position so the choice is reproducible
        order = np.lexsort(tuple(tree.origin[sel].T[::-1]) + (-lev.astype(int),))
        for i in sel[order[:per_material]]:
            size = 1 << int(tree.level[i])
            start = tuple(int(v) for v in tree.origin[i])
            boxes.append(SampleBox(int(label), start, tuple(v + size for v in start)))
        name = (names or {}).get(int(label), f"material {int(label)}")
        materials.append(Material(int(label), name))
    if not materials:
        raise ValueError("truth has no material labels above 0; nothing to sample.")
    return Samples(materials, boxes)
