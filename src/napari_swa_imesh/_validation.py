"""Checks at the door of every public function: one place, one wording.

Public functions call these and then trust their input; private workers never
re-check. Every error says what was expected, what came, and what to do.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["SPACING_RANGE", "IMAGE_NDIM", "as_image", "as_labels", "check_ndim",
           "normalize_spacing", "label_dtype", "OptionError"]

#: Dimensionalities every command and pipeline function takes: a plane or a volume (a
#: 4-D array is a time series or a stack of channels, which no step models).
IMAGE_NDIM = (2, 3)


def check_ndim(shape, *, name: str = "image", min_ndim: int = IMAGE_NDIM[0],
               max_ndim: int | None = IMAGE_NDIM[-1]) -> None:
    """Raise ValueError unless an array of `shape` has `min_ndim` .. `max_ndim` axes.

    The one check of dimensionality: :func:`as_image`, :func:`as_labels` and the readers of
    images kept on disk (Zarr, memory-mapped ``.npy``) all call it, so every command
    refuses the same arrays with the same sentence.

    Examples
    --------
    >>> check_ndim((4, 5, 6))
    >>> check_ndim((4, 5, 6, 2))
    Traceback (most recent call last):
    ...
    ValueError: image must be 2-D to 3-D; got 4-D with shape (4, 5, 6, 2). Squeeze ...
    """
    shape = tuple(int(n) for n in shape)
    if len(shape) < min_ndim or (max_ndim is not None and len(shape) > max_ndim):
        want = f"{min_ndim}-D" if max_ndim == min_ndim else (
            f"{min_ndim}-D to {max_ndim}-D" if max_ndim else f"at least {min_ndim}-D")
        raise ValueError(
            f"{name} must be {want}; got {len(shape)}-D with shape {shape}. Squeeze "
            "singleton axes or pass a single plane/volume (one time point or channel)."
        )



def as_image(
    image, *, name: str = "image", min_ndim: int = 2, max_ndim: int | None = None,
    copy: bool = True,
) -> np.ndarray:
    """Return `image` as a float array after checking it is a single-channel image.

    Parameters
    ----------
    image : array_like
        Grey-level image, 2-D or more, axes in numpy/napari order.
    name : str
        What to call it in error messages.
    min_ndim, max_ndim : int
        Accepted range of dimensionality (:func:`check_ndim`): the pipeline's doors
        pass :data:`IMAGE_NDIM`; the n-D feature transforms take any.
    copy : bool
        True: a new float64 array. False: float32 and float64 input come back as they
        are (no copy; read it, do not write to it), other numbers as float64.

    Returns
    -------
    (M, N[, P, ...]) ndarray of float64 (or float32 with ``copy=False``)

    Raises
    ------
    TypeError
        For complex, boolean-free object or string arrays.
    ValueError
        For RGB(A) images, wrong dimensionality, empty arrays and NaN or infinite values.

    Examples
    --------
    >>> img = np.zeros((2, 2), np.float32)
    >>> as_image(img, copy=False) is img, as_image(img).dtype
    (True, dtype('float64'))
    """
    arr = np.asarray(image)
    if arr.dtype.kind not in "biuf":
        raise TypeError(
            f"{name} must hold real numbers; got dtype {arr.dtype}. "
            "Convert it to a numeric grey-level array first."
        )
    if arr.ndim == 3 and arr.shape[-1] in (3, 4) and min(arr.shape[:2]) > 4:
        raise ValueError(
            f"{name} of shape {arr.shape} looks like an RGB(A) picture; a single channel "
            "is needed. Convert it to grey first (e.g. skimage.color.rgb2gray, or "
            "`--gray` on the command line), or pick one channel."
        )
    check_ndim(arr.shape, name=name, min_ndim=min_ndim, max_ndim=max_ndim)
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape}); give an image with pixels.")
    if copy or arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64, copy=True)
    # min and max are NaN or infinite when any value is: two reductions, no mask array
    if arr.dtype.kind == "f" and not (np.isfinite(arr.min()) and np.isfinite(arr.max())):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(
            f"{name} has {bad} NaN or infinite value(s); fill or mask them first "
            "(e.g. numpy.nan_to_num or replace them with a neighbouring value)."
        )
    return arr


def as_labels(
    labels, *, name: str = "labels", min_ndim: int = 1, max_ndim: int | None = None
) -> np.ndarray:
    """Return `labels` as a non-negative integer array, without copying integer input.

    Integer arrays come back as they are (same object's data, same dtype: a uint8 volume
    stays one byte per voxel), booleans as a uint8 view; whole-valued floats (label images
    saved as float are common) are converted once. Anything else is an error.

    Parameters
    ----------
    labels : array_like of int
        Label image; 0 means background, 1..K materials.
    name : str
        What to call it in error messages.
    min_ndim, max_ndim : int
        Accepted range of dimensionality.

    Returns
    -------
    ndarray of int or uint
        Integer input itself (read it, do not write to it), a uint8 view of boolean input,
        or an int32 (int64 when needed) copy of whole-valued float input. Every value lies
        in ``0 .. 2**63 - 1``, so it fits int64 exactly.

    Raises
    ------
    TypeError
        For non-numeric arrays.
    ValueError
        For wrong dimensionality, empty arrays, fractional, NaN or negative values, and
        values above ``2**63 - 1``.

    Examples
    --------
    >>> lab = np.array([[0, 1], [2, 2]], np.uint8)
    >>> as_labels(lab) is lab
    True
    >>> as_labels(np.array([[1.0, 2.0]])).dtype
    dtype('int32')
    """
    arr = np.asarray(labels)
    check_ndim(arr.shape, name=name, min_ndim=min_ndim, max_ndim=max_ndim)
    if arr.size == 0:
        raise ValueError(
            f"{name} is empty (shape {_plain(arr.shape)}); give a label image with pixels.")
    if arr.dtype.kind == "b":
        return arr.view(np.uint8)
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or not np.array_equal(arr, np.round(arr)):
            raise ValueError(
                f"{name} has non-integer values (dtype {arr.dtype}); a label image holds "
                "whole numbers 0..K. Segment or round the image first."
            )
    elif arr.dtype.kind not in "iu":
        raise TypeError(
            f"{name} must be an integer array; got dtype {arr.dtype}. Give whole-number "
            "material ids 0..K."
        )
    lo, hi = arr.min(), arr.max()
    if lo < 0:
        raise ValueError(
            f"{name} has negative values (min {_plain(lo)}); labels must be 0 (background) "
            "or positive material ids. Shift or relabel them first."
        )
    # int64 holds every material id exactly (the tree, the mesh and the file formats);
    # compare as Python numbers: uint64 against an int64 bound is not exact in numpy
    if _plain(hi) > _INT64_MAX:
        raise ValueError(
            f"{name} has values up to {_plain(hi)}, above {_INT64_MAX} (2**63 - 1), the "
            "largest material id that is kept exactly; relabel them to 0..K first (e.g. "
            "skimage.segmentation.relabel_sequential)."
        )
    if arr.dtype.kind == "f":
        # compared as Python numbers: numpy would cast the bound to float16 (overflow)
        return arr.astype(_dtype_for(0, _plain(hi), smallest=False))
    return arr


_INT64_MAX = int(np.iinfo(np.int64).max)


def _plain(value):
    """`value` (a numpy scalar, or a tuple of them) as plain Python numbers for messages.

    f-strings print numpy 2 scalars inside containers as ``np.float64(0.5)``; a command
    line user should read ``0.5``.

    Examples
    --------
    >>> _plain((np.float64(0.5), np.int64(3)))
    (0.5, 3)
    """
    if isinstance(value, (tuple, list)):
        return type(value)(_plain(v) for v in value)
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


SPACING_RANGE = (1e-30, 1e30)
"""Accepted spacing values. Metrics multiply up to six lengths (squared areas, products
of edge lengths), so a value outside this range could overflow to inf or underflow to 0
in float64 (range about 1e-308 .. 1e308) and give NaN qualities."""


def normalize_spacing(spacing: float | Sequence[float] | None, ndim: int) -> tuple[float, ...]:
    """Return voxel spacing as one positive float per axis.

    Parameters
    ----------
    spacing : float or sequence of float or None
        A scalar (isotropic), one value per axis, or None for 1.0. Every value must lie
        in :data:`SPACING_RANGE` (1e-30 .. 1e30), so the aspect ratio is at most 1e60 and
        products of lengths stay finite and non-zero.
    ndim : int
        Number of image axes.

    Raises
    ------
    ValueError
        For the wrong number of values, values that are not positive and finite, or
        values outside :data:`SPACING_RANGE`.

    Examples
    --------
    >>> normalize_spacing(0.5, 3)
    (0.5, 0.5, 0.5)
    """
    if spacing is None:
        return (1.0,) * ndim
    try:
        values = np.atleast_1d(np.asarray(spacing, dtype=float))
    except (TypeError, ValueError):
        values = None
    if values is None or values.ndim != 1 or values.size not in (1, ndim):
        raise ValueError(
            f"spacing must be one number or {ndim} numbers (one per axis); got "
            f"{_plain_text(spacing)}."
        )
    shown = ", ".join(f"{v:g}" for v in values)
    if values.size == 1:
        values = np.repeat(values, ndim)
    if not (np.isfinite(values).all() and (values > 0).all()):
        raise ValueError(f"spacing values must be positive and finite; got {shown}.")
    lo, hi = SPACING_RANGE
    if not ((values >= lo) & (values <= hi)).all():
        raise ValueError(
            f"spacing values must lie between {lo:g} and {hi:g} so that lengths, areas and "
            f"volumes stay finite; got {shown}. Express the spacing in other units (e.g. "
            "micrometres instead of metres)."
        )
    return tuple(float(v) for v in values)


def label_dtype(labels, *, smallest: bool = False, name: str = "labels") -> np.dtype:
    """The dtype labels are held in: the one label-dtype policy of the package.

    Labels computed on are int32, int64 when a value needs it (integer arrays that pass
    :func:`as_labels` are kept as they come; whole-valued floats become this dtype).
    Labels written to a file or shown (`smallest`) take the smallest integer dtype that
    holds every value: uint8 .. uint64 when none is negative, else int8 .. int64
    (:func:`~napari_swa_imesh.io.label_array`). Booleans count as 0 and 1.

    Parameters
    ----------
    labels : array_like of int
        The label values (an image, or the list of material ids).
    smallest : bool
        The file/display dtype instead of the compute dtype.
    name : str
        What to call `labels` in error messages.

    Returns
    -------
    numpy.dtype

    Raises
    ------
    ValueError
        With `smallest`, for values that no 64-bit integer type holds.

    Examples
    --------
    >>> label_dtype([1, 2]), label_dtype([1, 2**40])
    (dtype('int32'), dtype('int64'))
    >>> label_dtype([0, 3, 70000], smallest=True), label_dtype([-1, 5], smallest=True)
    (dtype('uint32'), dtype('int8'))
    """
    arr = np.asarray(labels)
    lo, hi = (int(arr.min()), int(arr.max())) if arr.size else (0, 0)
    dtype = _dtype_for(lo, hi, smallest=smallest)
    if dtype is None:
        raise ValueError(f"{name} span {lo} .. {hi}, which no 64-bit integer type holds; "
                         "relabel them first.")
    return dtype


def _dtype_for(lo, hi, *, smallest: bool) -> np.dtype | None:
    """:func:`label_dtype` of values from `lo` to `hi` (Python numbers: exact compares);
    None when `smallest` and no 64-bit integer type holds them."""
    if not smallest:
        return np.dtype(np.int32 if hi <= np.iinfo(np.int32).max else np.int64)
    kinds = (np.uint8, np.uint16, np.uint32, np.uint64) if lo >= 0 else (
        np.int8, np.int16, np.int32, np.int64)
    for dtype in kinds:
        info = np.iinfo(dtype)
        if info.min <= lo and hi <= info.max:
            return np.dtype(dtype)
    return None


def _plain_text(value) -> str:
    """A spacing-like argument as plain text: numbers joined by commas, else its str."""
    value = _plain(value)
    if isinstance(value, (tuple, list)):
        return ", ".join(str(v) for v in value) if value else "nothing"
    return str(value)


class OptionError(ValueError):
    """A bad value of one named option, worded so each caller can name it its own way.

    The message is `template` filled with ``option`` (the option's name) and `words`; the
    library raises it with its keyword's name, the command line re-words it with its
    flag (:meth:`as_option`) instead of editing the text.

    Examples
    --------
    >>> err = OptionError("facet_groups", "{option} lists no group; {drop}.",
    ...                   drop="pass 'none'")
    >>> str(err)
    "facet_groups lists no group; pass 'none'."
    >>> str(err.as_option("--facet-groups", drop="use --facet-groups none"))
    '--facet-groups lists no group; use --facet-groups none.'
    """

    def __init__(self, option: str, template: str, **words: str):
        self.option, self.template, self.words = option, template, words
        super().__init__(template.format(option=option, **words))

    @staticmethod
    def quote(value) -> str:
        """``repr(value)`` with its braces doubled, to put a given value in a template."""
        return repr(value).replace("{", "{{").replace("}", "}}")

    def as_option(self, option: str, **words: str) -> OptionError:
        """The same error naming the option `option` (and any of its words replaced)."""
        return OptionError(option, self.template, **{**self.words, **words})
