"""Tile moments (mean, variance, skewness, kurtosis) for all scales at once.

Reference eqs. 2.17-2.20. A tile at scale ``j`` is a block of ``2**j`` pixels per
axis starting at index 0; the tile grid has ``ceil(N_a / 2**j)`` tiles along axis
``a`` and the last tile along an axis may be partial.

Numerical scheme
----------------
The pyramid is built bottom-up (the Haar-pyramid tie: a tile at scale ``j`` is
the union of its ``2**d`` children at scale ``j - 1``). Each level keeps, per tile,
the count ``n``, a centre ``m`` (the mean up to rounding) and the power sums
about it ``M_p = sum (x - m)**p`` for p = 1..4; a parent merges its children
with the exact binomial shift (Chan et al. 1979, Pebay 2008), with
``delta = m_child - m_parent``::

    M1 = sum_c M1_c + n_c delta
    M2 = sum_c M2_c + 2 delta M1_c + n_c delta**2
    M3 = sum_c M3_c + 3 delta M2_c + 3 delta**2 M1_c + n_c delta**3
    M4 = sum_c M4_c + 4 delta M3_c + 6 delta**2 M2_c + 4 delta**3 M1_c + n_c delta**4

``M1`` is zero in exact arithmetic; carrying it cancels the rounding error of
the centres (the corrected two-pass algorithm), which otherwise shows at the
1e-9 level for data with an offset 1e7 times its spread.

Raw power sums of x..x**4 are *not* used: for data with a large offset (uint16
CT, 1e4 + noise) they cancel catastrophically. Scale 1 is computed two-pass from
the pixels (block mean, then powers of the deviations). Padding (odd sides are
padded by one zero-count tile per level) and masked-out pixels have count 0 and
so never enter a statistic. Cost is O(N) for all scales together.

Conventions
-----------
- Population moments (``ddof=0``); kurtosis is Pearson's ``m4 / m2**2`` (3 for a
  normal distribution), not the excess kurtosis.
- A tile whose standard deviation is numerically zero (``std <= 1e-13 * |mean|``,
  which includes ``std == 0``) gets skewness 0 and kurtosis 3, the values of a
  normal distribution: a constant tile gives no evidence of shape.
- A tile with no valid pixel gets NaN for all four moments.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator

import numpy as np

from napari_swa_imesh._validation import as_image

from ._tiles import block_spread, block_view, pad_to_even, pair_sum, validate_mask, validate_scale

__all__ = ["MOMENT_NAMES", "moment_pyramid", "tile_moments"]

MOMENT_NAMES = ("mean", "variance", "skewness", "kurtosis")

# A tile's std below this fraction of |mean| is rounding noise of the mean itself
# (a few ulps per level), not spread in the data.
ZERO_STD_RTOL = 1e-13
# Pixels per slab of the scale-1 pass (2 MB of float64: stays in cache).
_SLAB_PIXELS = 2**18


# ------------------------------------------------------------------ the levels
def _pixel_moments(x: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Scale-0 entry: every pixel is its own tile."""
    # zeros + two column writes: assigning a (0, 0, 3) row pattern is ~5x slower
    moments = np.zeros(x.shape + (4,), dtype=np.float64)
    moments[..., 0] = x
    moments[..., 3] = 3.0
    if valid is None:
        return moments, np.ones(x.shape, dtype=np.int64)
    moments[~valid] = np.nan
    return moments, valid.astype(np.int64)


def _first_level_slab(x: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """Scale-1 ``(centre, M1..M4, n)`` of a slab, two-pass from the pixels.

    `x` is a float64 copy the function may overwrite; sides are even.
    """
    if valid is None:
        n = np.full(tuple(side // 2 for side in x.shape), 2**x.ndim, dtype=np.int64)
    else:
        x *= valid
        n = pair_sum(valid.view(np.uint8), dtype=np.int64)
    mean = pair_sum(x)
    mean /= np.maximum(n, 1)
    block_view(x, 2)[...] -= block_spread(mean)  # x now holds deviations from the tile mean
    if valid is not None:
        x *= valid
    m1 = pair_sum(x)  # zero but for the rounding of `mean`; carried to cancel it
    power = x * x
    m2 = pair_sum(power)
    power *= x
    m3 = pair_sum(power)
    power *= x
    m4 = pair_sum(power)
    return mean, m1, m2, m3, m4, n


def _first_level(x: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """Scale-1 sums of the whole image, slab by slab along axis 0.

    Slabs of about `_SLAB_PIXELS` keep every temporary in cache, avoid
    image-sized buffers, and leave `x` untouched. Odd sides are padded per slab
    with zero-count pixels.
    """
    coarse = tuple(-(-side // 2) for side in x.shape)
    out = tuple(np.empty(coarse) for _ in range(5)) + (np.empty(coarse, dtype=np.int64),)
    row_pixels = int(np.prod(x.shape[1:]))
    rows = max(2, _SLAB_PIXELS // row_pixels // 2 * 2)  # even, so slabs align with tiles
    for first in range(0, x.shape[0], rows):
        slab = x[first:first + rows]
        slab_valid = None if valid is None else valid[first:first + rows]
        if any(side % 2 for side in slab.shape):
            if slab_valid is None:
                slab_valid = np.ones(slab.shape, dtype=bool)
            slab = pad_to_even(np.asarray(slab, np.float64), 0.0)
            slab_valid = pad_to_even(slab_valid, False)
        else:
            slab = np.array(slab, np.float64)       # a copy: the slab pass works in place
        target = slice(first // 2, first // 2 + slab.shape[0] // 2)
        for array, part in zip(out, _first_level_slab(slab, slab_valid)):
            array[target] = part
    return out


def _iter_moment_levels(
    x: np.ndarray, valid: np.ndarray | None, max_scale: int
) -> Iterator[tuple[np.ndarray, ...]]:
    """Yield ``(centre, M1, M2, M3, M4, n)`` per tile for scales 1..max_scale.

    `x` is float32 or float64 (taken to float64 slab by slab) and is not modified.
    Empty tiles have centre 0 and zero power sums, so they drop out of every merge.
    """
    if max_scale < 1:
        return
    mean, m1, m2, m3, m4, n = _first_level(x, valid)
    yield mean, m1, m2, m3, m4, n

    for _ in range(2, max_scale + 1):
        # Children, padded with empty tiles (n = 0) to even sides.
        mean_c, m1_c, m2_c, m3_c, m4_c, n_c = (
            pad_to_even(a) for a in (mean, m1, m2, m3, m4, n))
        weight_c = n_c.astype(np.float64)
        n = pair_sum(n_c)
        mean = pair_sum(weight_c * mean_c + m1_c)
        mean /= np.maximum(n, 1)
        # delta = child centre - parent centre, shape of the children grid
        delta = (block_view(mean_c, 2) - block_spread(mean)).reshape(mean_c.shape)
        n_delta = weight_c * delta
        m4 = pair_sum(m4_c + delta * (4.0 * m3_c + delta * (
            6.0 * m2_c + delta * (4.0 * m1_c + n_delta))))
        m3 = pair_sum(m3_c + delta * (3.0 * m2_c + delta * (3.0 * m1_c + n_delta)))
        m2 = pair_sum(m2_c + delta * (2.0 * m1_c + n_delta))
        m1 = pair_sum(m1_c + n_delta)
        yield mean, m1, m2, m3, m4, n


def _finalize_into(moments: np.ndarray, mean: np.ndarray, m1: np.ndarray, m2: np.ndarray,
                   m3: np.ndarray, m4: np.ndarray, n: np.ndarray) -> None:
    """Write the (..., 4) moments of one slab of tiles into `moments`."""
    inv_n = 1.0 / np.maximum(n, 1)
    # Power sums are about `mean`; shift them by the tiny residual c = M1 / n to the
    # true mean (corrected two-pass: Chan, Golub and LeVeque 1983).
    c = m1 * inv_n
    c2 = c * c
    s2 = m2 * inv_n
    s3 = m3 * inv_n
    var = s2 - c2
    np.maximum(var, 0.0, out=var)
    mu3 = s3 - c * (3.0 * s2 - 2.0 * c2)
    mu4 = m4 * inv_n
    mu4 -= c * (4.0 * s3 - c * (6.0 * s2 - 3.0 * c2))
    np.add(mean, c, out=moments[..., 0])
    moments[..., 1] = var
    flat = np.sqrt(var) <= ZERO_STD_RTOL * np.abs(moments[..., 0])
    var[flat] = 1.0
    std = np.sqrt(var)
    mu3 /= var * std
    mu4 /= var * var
    mu3[flat] = 0.0
    mu4[flat] = 3.0
    moments[..., 2] = mu3
    moments[..., 3] = mu4
    moments[n == 0] = np.nan


def _finalize(mean: np.ndarray, m1: np.ndarray, m2: np.ndarray, m3: np.ndarray,
              m4: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Turn a level's sums into the (..., 4) moments array and the counts."""
    moments = np.empty(mean.shape + (4,), dtype=np.float64)
    # slabs of tiles: the dozen temporaries stay cache-sized
    rows = max(1, _SLAB_PIXELS // 4 // max(1, int(np.prod(mean.shape[1:]))))
    for first in range(0, mean.shape[0], rows):
        part = slice(first, first + rows)
        _finalize_into(moments[part], mean[part], m1[part], m2[part], m3[part], m4[part], n[part])
    return moments, n


# ---------------------------------------------------------------- public layer
def moment_pyramid(
    image, *, max_scale: int, mask=None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Tile moments at every scale 0..max_scale, in O(N) total.

    Parameters
    ----------
    image : (N_0, ..., N_{d-1}) array_like of real numbers
        Grey-level image, 2-D or more, any real dtype (computed in float64). Sides
        need not be powers of two. Not modified.
    max_scale : int
        Largest scale, in ``0 .. floor(log2(max(image.shape)))``.
    mask : (N_0, ..., N_{d-1}) array_like of bool, optional
        True where a pixel counts. Default: every pixel.

    Returns
    -------
    list of (moments, counts)
        Entry ``j`` holds, on the tile grid ``t_a = ceil(N_a / 2**j)``:

        moments : (t_0, ..., t_{d-1}, 4) ndarray of float64
            Population mean, variance, skewness and (Pearson, not excess)
            kurtosis of the valid pixels of each tile; skewness 0 and kurtosis 3
            for tiles with numerically zero variance, NaN for tiles with no
            valid pixel.
        counts : (t_0, ..., t_{d-1}) ndarray of int64
            Number of valid pixels per tile (``2**(j*d)`` for a full tile).

    Examples
    --------
    >>> image = np.array([[0, 0, 1], [0, 4, 1]], dtype=np.uint8)
    >>> moments, counts = moment_pyramid(image, max_scale=1)[1]
    >>> counts
    array([[4, 2]])
    >>> moments[0, :, :2]  # (mean, variance) of [0, 0, 0, 4] and of [1, 1]
    array([[1., 3.],
           [1., 0.]])
    >>> moments[0, 1, 2:]  # constant tile: skewness 0, kurtosis 3 by convention
    array([0., 3.])
    """
    x = as_image(image, copy=False)
    valid = validate_mask(mask, x.shape)
    max_scale = validate_scale(max_scale, x.shape, name="max_scale")
    return moment_pyramid_unchecked(x, valid, max_scale)


def moment_pyramid_unchecked(x: np.ndarray, valid: np.ndarray | None, max_scale: int
                             ) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`moment_pyramid` of checked float input (not modified)."""
    pyramid = [_pixel_moments(x, valid)]
    for level in _iter_moment_levels(x, valid, max_scale):
        pyramid.append(_finalize(*level))
    return pyramid


def tile_moments_worker(x: np.ndarray, valid: np.ndarray | None,
                         scale: int) -> tuple[np.ndarray, np.ndarray]:
    """`tile_moments` on checked input (not modified)."""
    if scale == 0:
        return _pixel_moments(x, valid)
    # run to the last level, keeping only it
    (level,) = deque(_iter_moment_levels(x, valid, scale), maxlen=1)
    return _finalize(*level)


def tile_moments(image, scale: int, *, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """Tile moments at one scale (entry `scale` of :func:`moment_pyramid`).

    Only the requested scale is kept in memory; the coarser-than-pixel levels
    below it are still built bottom-up (O(N)).

    Parameters
    ----------
    image : (N_0, ..., N_{d-1}) array_like of real numbers
        Grey-level image, 2-D or more.
    scale : int
        Tiles of ``2**scale`` pixels per axis, ``0 .. floor(log2(max side))``.
    mask : (N_0, ..., N_{d-1}) array_like of bool, optional
        True where a pixel counts.

    Returns
    -------
    moments : (t_0, ..., t_{d-1}, 4) ndarray of float64
        Mean, variance, skewness, kurtosis (see :func:`moment_pyramid`).
    counts : (t_0, ..., t_{d-1}) ndarray of int64
        Valid pixels per tile.

    Examples
    --------
    >>> moments, counts = tile_moments(np.arange(16.0).reshape(4, 4), 2)
    >>> moments[0, 0, :2].tolist(), counts.tolist()  # mean, variance of 0..15
    ([7.5, 21.25], [[16]])
    """
    x = as_image(image, copy=False)
    valid = validate_mask(mask, x.shape)
    scale = validate_scale(scale, x.shape)
    return tile_moments_worker(x, valid, scale)
