"""n-D orthonormal Haar wavelet pyramid (reference eqs. 2.9-2.16).

One level is a fold over axes, as in ``pywt.dwtn``: along each axis in turn,
every pair of neighbours ``(a, b)`` becomes a low-pass coefficient
``(a + b) / sqrt(2)`` and a high-pass coefficient ``(a - b) / sqrt(2)``. After
all ``d`` axes there are ``2**d`` bands on a grid half the size per axis.

Band convention
---------------
Bands are numbered ``n = 0 .. 2**d - 1`` by the binary index of their high-pass
axes, axis 0 being the most significant bit: axis ``a`` is high-pass in band
``n`` iff bit ``d - 1 - a`` of ``n`` is set. Band 0 is the approximation ``L``;
the detail bands ``D^1 .. D^(2**d - 1)`` are stored in that order. In 2-D:
``D^1`` is high-pass along axis 1 (columns), ``D^2`` along axis 0 (rows),
``D^3`` along both. Coefficients at a coarse position ``p`` are computed from
the input block ``[2p, 2p + 2)`` per axis, so a tile of ``2**j`` pixels per
axis owns exactly the coefficients of levels ``k <= j`` that lie under it.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

__all__ = ["haar_analysis", "haar_synthesis"]

_INV_SQRT2 = 1.0 / np.sqrt(2.0)


def _check_real_array(image, name: str = "image") -> np.ndarray:
    arr = np.asarray(image)
    if arr.dtype.kind not in "biuf":
        raise TypeError(
            f"{name} must hold real numbers; got dtype {arr.dtype}. "
            "Convert it to a numeric array first."
        )
    if arr.ndim == 0:
        raise ValueError(f"{name} must have at least one axis; got a scalar.")
    return arr


def _check_levels(levels) -> int:
    if isinstance(levels, (bool, np.bool_)) or not isinstance(levels, (int, np.integer)):
        raise TypeError(f"levels must be an int; got {levels!r} of type {type(levels).__name__}.")
    if levels < 0:
        raise ValueError(f"levels must be >= 0; got {levels}.")
    return int(levels)


def _haar_one_level(approx: np.ndarray) -> np.ndarray:
    """One analysis level of a float64 array with even sides.

    Returns shape ``(2**d,) + coarse_shape``, bands in the documented order.
    """
    ndim = approx.ndim
    coarse = tuple(side // 2 for side in approx.shape)
    # (c_0, 2, c_1, 2, ...) -> (2, ..., 2, c_0, c_1, ...): one strided copy, after
    # which every butterfly below works on contiguous halves.
    split = approx.reshape([n for side in coarse for n in (side, 2)])
    order = tuple(range(1, 2 * ndim, 2)) + tuple(range(0, 2 * ndim, 2))
    bands = np.empty((2,) * ndim + coarse, dtype=np.float64)
    bands[...] = split.transpose(order)
    scratch = np.empty((2,) * (ndim - 1) + coarse, dtype=np.float64)
    for axis in range(ndim):
        lead = (slice(None),) * axis
        even, odd = bands[lead + (0,)], bands[lead + (1,)]
        np.subtract(even, odd, out=scratch)
        even += odd
        odd[...] = scratch
    # the d factors 1/sqrt(2) applied at once
    bands *= 2.0 ** (-ndim / 2)
    return bands.reshape((2**ndim,) + coarse)


def iter_haar_levels(image: np.ndarray, levels: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield ``(approx_k, details_k)`` for k = 1..levels (float64, sides already checked)."""
    approx = image
    for _ in range(levels):
        bands = _haar_one_level(approx)
        approx = bands[0]
        yield approx, bands[1:]


def haar_analysis(image, levels: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Orthonormal n-D Haar wavelet analysis to depth `levels`.

    Parameters
    ----------
    image : (N_0, ..., N_{d-1}) array_like of real numbers
        Any real dtype; computed in float64. Every side must be a multiple of
        ``2**levels`` (pad before calling, e.g. with ``numpy.pad``).
    levels : int
        Number of levels, >= 0.

    Returns
    -------
    approx : (N_0 / 2**levels, ...) ndarray of float64
        Approximation ``L_levels``.
    details : list of ndarray of float64
        ``details[k - 1]`` has shape ``(2**d - 1, N_0 / 2**k, ...)`` and holds the
        detail bands ``D_k^1 .. D_k^(2**d - 1)`` of level ``k`` (band order in the
        module docstring: binary index of the high-pass axes, axis 0 most
        significant).

    Raises
    ------
    ValueError
        If a side is not a multiple of ``2**levels``.

    Examples
    --------
    >>> approx, details = haar_analysis(np.array([[1.0, 3.0], [5.0, 7.0]]), 1)
    >>> approx
    array([[8.]])
    >>> details[0][:, 0, 0]  # high-pass along axis 1, axis 0, both
    array([-2., -4.,  0.])
    """
    arr = _check_real_array(image)
    levels = _check_levels(levels)
    block = 2**levels
    if any(side % block for side in arr.shape):
        raise ValueError(
            f"haar_analysis to {levels} level(s) needs every side to be a multiple of "
            f"2**{levels} = {block}; got shape {arr.shape}. Pad the image first "
            "(e.g. numpy.pad with mode='symmetric')."
        )
    approx = arr.astype(np.float64, copy=True)
    details: list[np.ndarray] = []
    for approx, level_details in iter_haar_levels(approx, levels):  # noqa: B007, B020 (the last level)
        details.append(level_details)
    return approx, details


def haar_synthesis(approx, details) -> np.ndarray:
    """Exact inverse of :func:`haar_analysis`.

    Parameters
    ----------
    approx : (M_0, ..., M_{d-1}) array_like of float
        Approximation at the coarsest level ``K = len(details)``.
    details : sequence of array_like
        ``details[k - 1]`` of shape ``(2**d - 1, M_0 * 2**(K - k), ...)``, as
        returned by :func:`haar_analysis`.

    Returns
    -------
    (M_0 * 2**K, ...) ndarray of float64
        The reconstructed image.

    Examples
    --------
    >>> image = np.arange(16.0).reshape(4, 4)
    >>> np.allclose(haar_synthesis(*haar_analysis(image, 2)), image)
    True
    """
    current = np.array(_check_real_array(approx, "approx"), dtype=np.float64)
    ndim = current.ndim
    for k in range(len(details), 0, -1):
        level = np.asarray(details[k - 1], dtype=np.float64)
        expected = (2**ndim - 1,) + current.shape
        if level.shape != expected:
            raise ValueError(
                f"details[{k - 1}] must have shape {expected} to match the level-{k} "
                f"approximation; got {level.shape}. Pass the list from haar_analysis unchanged."
            )
        bands = np.concatenate([current[np.newaxis], level], axis=0)  # (2**d, *coarse)
        # Undo the fold in reverse axis order: the last axis is the least significant bit.
        for axis in range(ndim, 0, -1):
            pairs = bands.reshape((-1, 2) + bands.shape[1:])
            low, high = pairs[:, 0], pairs[:, 1]
            even = (low + high) * _INV_SQRT2
            odd = (low - high) * _INV_SQRT2
            # interleave along `axis`: (B, ..., n, ...) -> (B, ..., n, 2, ...) -> (B, ..., 2n, ...)
            merged = np.stack([even, odd], axis=axis + 1)
            shape = list(even.shape)
            shape[axis] *= 2
            bands = merged.reshape(shape)
        current = bands[0]
    return current
