"""Integer points packed in one int64 per vertex, for passes over the elements' corners.

Gathering a corner's coordinates axis by axis costs d random reads per corner; packed,
one read brings all d (fields of ``63 // d`` bits, axis 0 highest) and shifts and masks
on the gathered values, in cache, unpack them. At volume size the gathers were most of
the time of the checks and of the facet groups.
"""

from __future__ import annotations

import zlib

import numpy as np

__all__ = ["pack_points", "corners", "unpack", "array_fingerprint"]

_FP_CHUNK = 1 << 16
_FP_WEIGHTS = (np.random.default_rng(0x5EED).integers(0, 2**63, _FP_CHUNK, dtype=np.uint64)
               * np.uint64(2) + np.uint64(1))        # odd: every value counts in every bit
_FP_MIX = np.uint64(0xBF58476D1CE4E5B9)


def pack_points(coords: np.ndarray) -> tuple[np.ndarray, int] | None:
    """(N,) int64 of the integer points `coords` (N, d), and the bits of a field; None when
    a value is not an integer in ``[0, 2**(63 // d))`` (a NaN included).

    Examples
    --------
    >>> packed, bits = pack_points(np.array([[1.0, 2.0], [3.0, 0.0], [0.0, 5.0]]))
    >>> p = corners(packed, np.array([[0, 1, 2]]), bits, 2)
    >>> bits, [[int(x[0]) for x in corner] for corner in p]
    (31, [[1, 2], [3, 0], [0, 5]])
    >>> pack_points(np.array([[0.5, 1.0]])) is None
    True
    """
    d = coords.shape[1]
    bits = 63 // d
    if not len(coords):
        return None
    packed = np.zeros(len(coords), dtype=np.int64)
    for a in range(d):
        x = coords[:, a]
        lo, hi = x.min(), x.max()
        if not (0 <= lo and hi < 1 << bits):
            return None
        xi = x.astype(np.int64)
        if x.dtype.kind == "f" and not np.array_equal(xi, x):
            return None
        packed <<= bits
        packed |= xi
    return packed, bits


def corners(packed: np.ndarray, ids: np.ndarray, bits: int, d: int, dtype=np.int64) -> list:
    """``p[k][a]``: coordinate `a` of corner `k` of the cells `ids` (n, d+1), (n,) of
    `dtype` (int32 holds every field: half the bytes for the arithmetic that follows)."""
    return unpack(packed[ids.T], bits, d, dtype)    # (d+1, n): one gather, rows contiguous


def unpack(q: np.ndarray, bits: int, d: int, dtype=np.int64) -> list:
    """``p[k][a]`` from the packed corners `q` (d+1, n)."""
    field = (1 << bits) - 1
    return [[((q[k] >> (bits * (d - 1 - a))) & field).astype(dtype, copy=False)
             for a in range(d)] for k in range(d + 1)]


def array_fingerprint(a: np.ndarray) -> int:
    """A 64-bit fingerprint of `a`'s values in order (with its shape and dtype), to tell
    whether an array changed since it was recorded: a weighted sum of its 8-byte words,
    each mixed (an odd multiply, its high half folded into the low) and weighted by a
    fixed random odd number, chunk by chunk, a few ns per word.

    Two different arrays share it with a chance of about 2**-64 each, unless chosen to.

    Examples
    --------
    >>> a = np.arange(6).reshape(3, 2)
    >>> array_fingerprint(a) == array_fingerprint(a.copy())
    True
    >>> array_fingerprint(a) == array_fingerprint(a[:, ::-1])
    False
    >>> x = np.ones(4)
    >>> array_fingerprint(x) == array_fingerprint(-x)      # four sign bits flipped
    False
    """
    data = np.ascontiguousarray(a).reshape(-1).view(np.uint8)
    if len(data) % 8:
        data = np.concatenate([data, np.zeros(8 - len(data) % 8, np.uint8)])
    words = data.view(np.uint64)
    h = len(words)
    for start in range(0, len(words), _FP_CHUNK):
        # mixed before the weighted sum, which alone is linear: a sign flip adds 2**63 to
        # a word, and any even number of them would cancel
        mixed = np.multiply(words[start:start + _FP_CHUNK], _FP_MIX)
        mixed ^= mixed >> np.uint64(32)
        mixed *= _FP_WEIGHTS[:len(mixed)]
        s = int(mixed.sum(dtype=np.uint64))
        h = (h * 0x9E3779B97F4A7C15 + s) & 0xFFFFFFFFFFFFFFFF
    layout = zlib.crc32(repr((np.shape(a), np.asarray(a).dtype.str)).encode())
    return (h * 0x9E3779B97F4A7C15 + layout) & 0xFFFFFFFFFFFFFFFF
