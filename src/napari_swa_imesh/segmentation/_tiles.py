"""The tile grid: its door checks, every block reduction, and the tile utilities.

Convention (reference eq. 2.7): a tile at scale ``j`` is a block of ``s = 2**j`` pixels per
axis starting at index 0; an image of shape ``(N_0, ..., N_{d-1})`` has ``ceil(N_a / s)``
tiles along axis ``a``, and the last tile along an axis may be partial (it holds
``N_a - s * (t_a - 1)`` pixels). Padding is always at the far end of an axis.

Every sum over blocks in the segmentation goes through :func:`block_sum`
(``skimage.measure.block_reduce``); the pyramid's 2 x ... x 2 fold (:func:`pair_sum`) is the
one hand-written reduction left, kept because it is about 3x faster on the hot path.
"""

from __future__ import annotations

import numpy as np
from skimage.measure import block_reduce

from .._validation import label_dtype, normalize_spacing

__all__ = ["validate_scale", "validate_mask", "block_view", "block_spread", "pad_to_even",
           "pair_sum", "block_sum", "block_mean", "block_counts", "tile_counts", "tile_means",
           "majority_tiles", "upsample_tiles", "tile_placement"]


# ---------------------------------------------------------------- door checks
def validate_scale(scale, shape: tuple[int, ...], name: str = "scale") -> int:
    """Return `scale` as int after checking 0 <= scale <= floor(log2(max side))."""
    top = int(max(shape)).bit_length() - 1
    if isinstance(scale, (bool, np.bool_)) or not isinstance(scale, (int, np.integer)):
        raise ValueError(
            f"{name} must be an int in 0..{top} for an image of shape {shape}; "
            f"got {scale!r} of type {type(scale).__name__}."
        )
    if not 0 <= scale <= top:
        raise ValueError(
            f"{name} must be an int in 0..{top} (floor(log2) of the largest side, "
            f"{max(shape)}) for an image of shape {shape}; got {scale}. Tiles are "
            f"2**{name} pixels per axis."
        )
    return int(scale)


def validate_mask(mask, shape: tuple[int, ...]) -> np.ndarray | None:
    """Return `mask` as a new bool array of `shape` (True = valid), or None."""
    if mask is None:
        return None
    arr = np.asarray(mask)
    if arr.dtype.kind not in "biu":
        raise TypeError(
            f"mask must be a boolean (or 0/1 integer) array; got dtype {arr.dtype}. "
            "Use e.g. `image > threshold` to build one."
        )
    if arr.shape != tuple(shape):
        raise ValueError(
            f"mask must have the image's shape {tuple(shape)}; got {arr.shape}. "
            "Build the mask on the same grid as the image."
        )
    return arr != 0


# ------------------------------------------------------------ block reductions
def block_view(arr: np.ndarray, block: int) -> np.ndarray:
    """View of shape (t_0, block, t_1, block, ...) of an array with sides multiple of `block`."""
    shape: list[int] = []
    for side in arr.shape:
        shape += [side // block, block]
    return arr.reshape(shape)


def block_spread(coarse: np.ndarray) -> np.ndarray:
    """View of shape (t_0, 1, t_1, 1, ...) that broadcasts against :func:`block_view`."""
    shape: list[int] = []
    for side in coarse.shape:
        shape += [side, 1]
    return coarse.reshape(shape)


def pad_to_even(arr: np.ndarray, fill=0) -> np.ndarray:
    """Pad every odd side by one element of `fill` at the end (no copy if all even)."""
    pad = [(0, side % 2) for side in arr.shape]
    if not any(after for _, after in pad):
        return arr
    return np.pad(arr, pad, mode="constant", constant_values=fill)


def pair_sum(arr: np.ndarray, dtype=None) -> np.ndarray:
    """Sum 2 x ... x 2 blocks of an array with even sides.

    Folding the last axis first is about 3x faster than ``reshape(...).sum(axes)``
    on a C-ordered volume (this runs once per pyramid level on the whole image).
    """
    out = arr
    for axis in range(arr.ndim - 1, -1, -1):
        lead = (slice(None),) * axis
        out = np.add(out[lead + (slice(0, None, 2),)], out[lead + (slice(1, None, 2),)],
                     dtype=dtype)
    return out


def block_sum(arr: np.ndarray, block, *, dtype=None) -> np.ndarray:
    """Sum over blocks of `block` px per axis (an int, or one per axis); partial blocks at
    the far edges sum what they hold (zero padding).

    Returns
    -------
    (ceil(N_0/block), ..., ceil(N_{d-1}/block)) ndarray
        Of `dtype` (default: numpy's sum dtype for `arr`).

    Examples
    --------
    >>> block_sum(np.arange(6).reshape(2, 3), 2).tolist()
    [[8, 7]]
    """
    return block_reduce(arr, block, np.sum, cval=0, func_kwargs={"dtype": dtype})


def block_counts(shape: tuple[int, ...], block: int) -> np.ndarray:
    """Pixels per block when every pixel counts: an outer product of per-axis counts
    (only the last block along an axis is partial)."""
    counts = np.ones((), dtype=np.int64)
    for side in shape:
        per_axis = np.minimum(block, side - block * np.arange(-(-side // block)))
        counts = np.multiply.outer(counts, per_axis.astype(np.int64))
    return counts


def block_mean(arr: np.ndarray, block: int) -> np.ndarray:
    """Mean over blocks of `block` px per axis; a partial block at the far edge is the
    mean of the pixels it holds.

    Examples
    --------
    >>> block_mean(np.array([[1.0, 3.0, 5.0]]), 2).tolist()
    [[2.0, 5.0]]
    """
    # float64 sums: a block of 2^k float32 pixels would lose k bits in float32
    return block_sum(arr, block, dtype=np.float64) / block_counts(arr.shape, block)


def tile_counts(shape: tuple[int, ...], scale: int, valid: np.ndarray | None) -> np.ndarray:
    """Valid pixels per tile at `scale`, shape ceil(shape / 2**scale), int64."""
    if valid is None:
        return block_counts(shape, 1 << scale)
    return block_sum(valid, 1 << scale, dtype=np.int64)


def tile_means(padded: np.ndarray, counts: np.ndarray, scale: int,
               valid_padded: np.ndarray | None = None) -> np.ndarray:
    """Mean over the valid pixels of each tile; `padded` has sides multiple of 2**scale.

    Tiles without a valid pixel get 0 (callers decide what that means).
    """
    data = padded if valid_padded is None else np.where(valid_padded, padded, 0.0)
    return block_sum(data, 1 << scale) / np.maximum(counts, 1)


# ------------------------------------------------------------------ tile labels
def majority_tiles(labels: np.ndarray, scale: int, materials) -> np.ndarray:
    """Most frequent label in every tile of 2^scale px per axis (last tiles may be partial).

    Ties go to the smallest label, so the result does not depend on the order in which
    `materials` are listed.

    Parameters
    ----------
    labels : ndarray of int
        Full-resolution labels.
    scale : int
        Tile scale j.
    materials : sequence of int
        The labels counted.

    Returns
    -------
    (ceil(M/2^scale), ceil(N/2^scale)[, ...]) ndarray of int32 (int64 for labels >= 2^31)

    Examples
    --------
    >>> majority_tiles(np.array([[1, 1, 2], [1, 2, 2]]), 1, [1, 2]).tolist()
    [[1, 2]]
    """
    values = np.sort(np.asarray(list(materials), label_dtype(materials)))
    if scale == 0:
        return np.asarray(labels, values.dtype).copy()
    s = 1 << scale
    counts = np.stack([block_sum(labels == m, s, dtype=np.int32) for m in values])
    return values[counts.argmax(axis=0)]


def upsample_tiles(tile_labels: np.ndarray, scale: int, shape: tuple[int, ...]) -> np.ndarray:
    """Full-resolution labels from tile labels: repeat each tile 2^scale times, crop to `shape`.

    Parameters
    ----------
    tile_labels : ndarray of int
        One label per tile.
    scale : int
        Tile scale j.
    shape : tuple of int
        Shape of the image.

    Returns
    -------
    ndarray of int
        Labels of `shape`, same dtype as `tile_labels`.

    Examples
    --------
    >>> upsample_tiles(np.array([[1, 2]]), 1, (2, 3)).tolist()
    [[1, 1, 2], [1, 1, 2]]
    """
    out = tile_labels
    s = 1 << scale
    for axis in range(tile_labels.ndim):
        out = np.repeat(out, s, axis=axis)
    return np.ascontiguousarray(out[tuple(slice(0, n) for n in shape)])


def tile_placement(scale: int, spacing=None, ndim: int | None = None
                   ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Spacing and origin of the tile grid in the image's physical frame.

    Pixel i's centre sits at ``i * spacing``; a tile of s = 2^scale pixels covers pixels
    t*s .. t*s+s-1, so its centre sits at ``t*s*spacing + (s-1)/2*spacing``. The command
    line writes these into the header of ``--tiles`` output; a napari Labels layer of tile
    labels takes them as its ``scale`` and ``translate``.

    Parameters
    ----------
    scale : int
        Tile scale j (tiles of 2^j px per axis).
    spacing : sequence of float or float, optional
        Pixel size per axis (default 1).
    ndim : int, optional
        Image dimensionality, when `spacing` does not give it.

    Returns
    -------
    spacing : tuple of float
        Tile size per axis in physical units.
    origin : tuple of float
        Centre of the first tile.

    Examples
    --------
    >>> tile_placement(1, (1.0, 0.5))
    ((2.0, 1.0), (0.5, 0.25))
    """
    sp = normalize_spacing(spacing, ndim if ndim is not None else len(spacing))
    s = 1 << scale
    return tuple(v * s for v in sp), tuple(v * (s - 1) / 2 for v in sp)
