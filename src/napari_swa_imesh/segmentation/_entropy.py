"""Multi-scale wavelet entropy per tile (reference eqs. 2.21-2.22).

For a set of coefficients ``Y``, ``H(Y) = -(1 / #Y) * sum |y| log|y|`` with the
natural logarithm and ``0 log 0 = 0``. A tile at scale ``j`` (``2**j`` pixels per
axis) owns one approximation coefficient of ``L_j`` and ``2**(d (j - k))``
coefficients of every detail band ``D_k^n`` (k = 1..j, n = 1..2**d - 1), because
the Haar pyramid of the whole image restricted to a dyadic tile is the pyramid
of the tile (see :mod:`._haar`). Hence one global transform serves all tiles.
"""

from __future__ import annotations

import numpy as np

from napari_swa_imesh._validation import as_image

from ._haar import iter_haar_levels
from ._tiles import block_spread, block_sum, block_view, tile_means, validate_mask, validate_scale

__all__ = ["entropy_feature_names", "tile_entropy"]

_SLAB_PIXELS = 2**18  # pixels per slab of tiles (2 MB of float64)


def entropy_feature_names(ndim: int, scale: int) -> list[str]:
    """Names of the ``(2**ndim - 1) * scale + 1`` entropy features, in output order.

    ``"entropy_L{j}"`` for the approximation at scale ``j``, then
    ``"entropy_D{k}_{n}"`` for level k = 1..j and detail band n = 1..2**ndim - 1
    (band numbering as in :mod:`._haar`: binary index of the high-pass axes,
    axis 0 most significant).

    Parameters
    ----------
    ndim : int
        Image dimensionality.
    scale : int
        Tile scale j.

    Returns
    -------
    list of str
        The names.

    Examples
    --------
    >>> entropy_feature_names(2, 1)
    ['entropy_L1', 'entropy_D1_1', 'entropy_D1_2', 'entropy_D1_3']
    """
    for value, what in ((ndim, "ndim"), (scale, "scale")):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"{what} must be an int; got {value!r}.")
    if ndim < 1 or scale < 0:
        raise ValueError(f"need ndim >= 1 and scale >= 0; got ndim={ndim}, scale={scale}.")
    names = [f"entropy_L{scale}"]
    for level in range(1, scale + 1):
        names += [f"entropy_D{level}_{band}" for band in range(1, 2**ndim)]
    return names


def _neg_abs_log(coeffs: np.ndarray) -> np.ndarray:
    """-|y| log|y| elementwise, 0 where y == 0 (float64, new array)."""
    magnitude = np.abs(coeffs)
    log = np.zeros_like(magnitude)
    np.log(magnitude, out=log, where=magnitude > 0)
    log *= magnitude
    np.negative(log, out=log)
    return log


def _prepare_padded(x: np.ndarray, valid: np.ndarray | None, scale: int
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """Mirror-pad to multiples of 2**scale; masked pixels -> their tile's valid mean.

    Returns the padded float64 image and, when a mask is given, the bool array of
    tiles without any valid pixel (else None).
    """
    block = 2**scale
    pad = [(0, (-side) % block) for side in x.shape]
    padded = np.pad(x, pad, mode="symmetric") if any(p for _, p in pad) else x
    if valid is None:
        return padded, None
    valid_padded = np.pad(valid, pad, mode="symmetric")
    counts = block_sum(valid_padded, block, dtype=np.int64)
    means = tile_means(padded, counts, scale, valid_padded)
    filled = np.where(valid_padded, padded, 0.0)
    block_view(filled, block)[...] += np.where(
        block_view(valid_padded, block), 0.0, block_spread(means))
    return filled, counts == 0


def _slab_entropy(padded: np.ndarray, scale: int) -> np.ndarray:
    """Entropy features of a slab whose sides are multiples of 2**scale."""
    ndim = padded.ndim
    n_bands = 2**ndim - 1
    grid = tuple(side // 2**scale for side in padded.shape)
    out = np.empty(grid + (n_bands * scale + 1,), dtype=np.float64)
    approx = padded
    for level, (approx, details) in enumerate(  # noqa: B007 (the last level is used below)
            iter_haar_levels(padded, scale), start=1):
        # details (B, c_0, ...) -> per-tile mean over blocks of 2**(scale - level)
        entropy = _neg_abs_log(details)
        block = 2 ** (scale - level)
        per_tile = block_sum(entropy, (1,) + (block,) * ndim) / block**ndim  # (B, *grid)
        start = 1 + (level - 1) * n_bands
        out[..., start:start + n_bands] = np.moveaxis(per_tile, 0, -1)
    out[..., 0] = _neg_abs_log(approx)
    return out


def tile_entropy_worker(x: np.ndarray, valid: np.ndarray | None, scale: int) -> np.ndarray:
    """`tile_entropy` on checked float64 input (not modified)."""
    padded, empty = _prepare_padded(x, valid, scale)
    tile = 2**scale
    grid = tuple(side // tile for side in padded.shape)
    out = np.empty(grid + ((2**x.ndim - 1) * scale + 1,), dtype=np.float64)
    # Slabs of whole tiles along axis 0 keep the coefficient buffers cache-sized.
    rows = max(1, _SLAB_PIXELS // (tile * int(np.prod(padded.shape[1:]))))
    for first in range(0, grid[0], rows):
        out[first:first + rows] = _slab_entropy(padded[first * tile:(first + rows) * tile], scale)
    if empty is not None:
        out[empty] = np.nan
    return out


def tile_entropy(image, scale: int, *, mask=None) -> np.ndarray:
    """Entropy of each tile's Haar coefficients, band by band (eq. 2.22).

    Parameters
    ----------
    image : (N_0, ..., N_{d-1}) array_like of real numbers
        Grey-level image, 2-D or more, any real dtype (computed in float64). Not
        modified.
    scale : int
        Tiles of ``2**scale`` pixels per axis, ``0 .. floor(log2(max side))``.
    mask : (N_0, ..., N_{d-1}) array_like of bool, optional
        True where a pixel counts. Masked-out pixels are replaced by the mean of
        the valid pixels of their (padded) tile before the transform, so they add
        no detail; tiles with no valid pixel get NaN.

    Returns
    -------
    (t_0, ..., t_{d-1}, (2**d - 1) * scale + 1) ndarray of float64
        ``t_a = ceil(N_a / 2**scale)``. Features in the order
        ``[H(L_j), H(D_1^1), ..., H(D_1^(2**d-1)), ..., H(D_j^(2**d-1))]``, named
        by :func:`entropy_feature_names`; natural logarithm.

    Notes
    -----
    The transform needs sides that are multiples of ``2**scale``: the image is
    padded at the far end of each axis by mirror reflection (``numpy.pad``
    mode ``"symmetric"``, edge pixel repeated). Tiles that overlap the padding
    still get features, computed partly from reflected real values; use the
    counts of :func:`~._moments.tile_moments` to tell full tiles from partial ones.

    Examples
    --------
    >>> image = np.array([[1.0, 1.0], [1.0, 1.0 + 2 * np.e]])
    >>> tile_entropy(image, 1).round(3).tolist()  # L = 2 + e, every |D| = e: H(D) = -e
    [[[-7.32, -2.718, -2.718, -2.718]]]
    """
    x = as_image(image)
    valid = validate_mask(mask, x.shape)
    scale = validate_scale(scale, x.shape)
    return tile_entropy_worker(x, valid, scale)

