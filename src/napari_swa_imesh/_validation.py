"""Checks at the door of every public function: one place, one wording.

Public functions call these and then trust their input; private workers never
re-check. Every error says what was expected, what came, and what to do.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["as_image", "as_labels", "normalize_spacing", "label_dtype"]


def as_image(
    image, *, name: str = "image", min_ndim: int = 2, max_ndim: int | None = None
) -> np.ndarray:
    """Return `image` as a float64 array after checking it is a single-channel image.

    Parameters
    ----------
    image : array_like
        Grey-level image, 2-D or more, axes in numpy/napari order.
    name : str
        What to call it in error messages.
    min_ndim, max_ndim : int
        Accepted range of dimensionality.

    Returns
    -------
    (M, N[, P, ...]) ndarray of float64
        A new array (the input is never modified).

    Raises
    ------
    TypeError
        For complex, boolean-free object or string arrays.
    ValueError
        For RGB(A) images, wrong dimensionality, empty arrays and NaN or infinite values.
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
    if arr.ndim < min_ndim or (max_ndim is not None and arr.ndim > max_ndim):
        want = f"{min_ndim}-D" if max_ndim == min_ndim else (
            f"{min_ndim}-D to {max_ndim}-D" if max_ndim else f"at least {min_ndim}-D")
        raise ValueError(
            f"{name} must be {want}; got {arr.ndim}-D with shape {arr.shape}. "
            "Squeeze singleton axes or pass a single plane/volume."
        )
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape}); give an image with pixels.")
    out = arr.astype(np.float64, copy=True)
    if not np.isfinite(out).all():
        bad = int(np.count_nonzero(~np.isfinite(out)))
        raise ValueError(
            f"{name} has {bad} NaN or infinite value(s); fill or mask them first "
            "(e.g. numpy.nan_to_num or replace them with a neighbouring value)."
        )
    return out


def as_labels(
    labels, *, name: str = "labels", min_ndim: int = 1, max_ndim: int | None = None
) -> np.ndarray:
    """Return `labels` as a non-negative integer array.

    Float arrays are accepted when every value is a whole number (label images
    saved as float are common); anything else is an error.

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
    ndarray of int32 or int64
        The smallest signed dtype of the two that holds every label.
    """
    arr = np.asarray(labels)
    if arr.ndim < min_ndim or (max_ndim is not None and arr.ndim > max_ndim):
        want = f"{min_ndim}-D to {max_ndim}-D" if max_ndim else f"at least {min_ndim}-D"
        raise ValueError(
            f"{name} must be {want}; got {arr.ndim}-D with shape {arr.shape}. "
            "Squeeze singleton axes or pass a single plane/volume."
        )
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape}); give a label image with pixels.")
    if arr.dtype.kind == "b":
        arr = arr.astype(np.int32)
    elif arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or not np.array_equal(arr, np.round(arr)):
            raise ValueError(
                f"{name} has non-integer values (dtype {arr.dtype}); a label image holds "
                "whole numbers 0..K. Segment or round the image first."
            )
    elif arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an integer array; got dtype {arr.dtype}.")
    if arr.min() < 0:
        raise ValueError(
            f"{name} has negative values (min {arr.min()}); labels must be 0 (background) "
            "or positive material ids. Shift or relabel them first."
        )
    top = arr.max()
    dtype = np.int32 if top < np.iinfo(np.int32).max else np.int64
    return arr.astype(dtype, copy=True)


def normalize_spacing(spacing: float | Sequence[float] | None, ndim: int) -> tuple[float, ...]:
    """Return voxel spacing as one positive float per axis.

    Parameters
    ----------
    spacing : float or sequence of float or None
        A scalar (isotropic), one value per axis, or None for 1.0.
    ndim : int
        Number of image axes.

    Examples
    --------
    >>> normalize_spacing(0.5, 3)
    (0.5, 0.5, 0.5)
    """
    if spacing is None:
        return (1.0,) * ndim
    values = np.atleast_1d(np.asarray(spacing, dtype=float))
    if values.ndim != 1 or values.size not in (1, ndim):
        raise ValueError(
            f"spacing must be one number or {ndim} numbers (one per axis); got {spacing!r}."
        )
    if values.size == 1:
        values = np.repeat(values, ndim)
    if not (np.isfinite(values).all() and (values > 0).all()):
        raise ValueError(f"spacing values must be positive and finite; got {tuple(values)}.")
    return tuple(float(v) for v in values)


def label_dtype(labels) -> np.dtype:
    """int32 when every label fits it, else int64 (labels are 1 .. 2^63 - 1).

    Examples
    --------
    >>> label_dtype([1, 2]), label_dtype([1, 2**40])
    (dtype('int32'), dtype('int64'))
    """
    top = max((int(v) for v in labels), default=0)
    return np.dtype(np.int32 if top <= np.iinfo(np.int32).max else np.int64)
