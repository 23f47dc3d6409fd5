"""Numbers as text, a whole block of rows at a time, for the text mesh formats.

Python's ``%`` formatting costs about 0.1 us per number, which made text writers (Abaqus
``.inp``, TetGen/Triangle, ASCII Gmsh) several times slower than the mesher at volume
size. Here the decimal digits of many numbers are made at once in numpy: eight digits
of a ``uint64`` are split in SWAR style (one multiply-shift per halving, every lane of a
64-bit word at once), and the word's little-endian bytes are then the digits, most
significant first. Each column of a block is right-aligned to the digits of its largest
value, padded with blanks, which every reader of these formats skips (they split on
commas or on whitespace and ignore blanks).

Blocks this cannot write (negative integers, integers of more than 16 digits, floats
outside 1e-30 .. 1e30 or not finite) return None, and callers use ``%`` formatting.
"""

from __future__ import annotations

import numpy as np

__all__ = ["int_rows", "sci_rows"]

_U = np.uint64
_POW10_F = 10.0 ** np.arange(23)          # exact as float64
_CHUNK = 1 << 16                          # values per pass (their temporaries stay in cache)
_ZEROS, _HIGH_BITS = _U(0x3030303030303030), _U(0x8080808080808080)


def _digits8(x: np.ndarray, blank: bool = True) -> np.ndarray:
    """The 8-digit decimal text of every `x` (uint64, each below 10**8) as the bytes of a
    uint64, most significant first (little-endian), with leading zeros as blanks when
    `blank` (a lone 0 stays "0").

    Every step halves the digit groups of all lanes of the word at once, dividing by a
    multiply and a shift that are exact in the range they see.
    """
    out = np.empty(x.shape, dtype=np.uint64)
    for s in range(0, len(x), _CHUNK):
        v = x[s:s + _CHUNK]
        hi = v * _U(109951163)                    # // 10**4: exact below 4.9e8
        hi >>= _U(40)
        t = hi * _U(10000)
        v = v - t
        v <<= _U(32)
        v |= hi                                   # two 4-digit lanes
        for mul, shift, mask, div, lane in ((5243, 19, 0x0000007F0000007F, 100, 16),
                                            (103, 10, 0x000F000F000F000F, 10, 8)):
            q = np.multiply(v, _U(mul), out=t)    # // 100 below 43699, // 10 below 179
            q >>= _U(shift)
            q &= _U(mask)
            hi = np.multiply(q, _U(div), out=hi)
            v -= hi
            v <<= _U(lane)
            v |= q                                # then four 2-digit, eight 1-digit lanes
        if blank:
            # the lowest nonzero byte (the first digit) by the lowest set bit of the
            # per-byte "nonzero" bits; the bytes below it are leading zeros
            first = np.add(v, _U(0x7F7F7F7F7F7F7F7F), out=hi)
            first &= _HIGH_BITS
            first |= _U(0x80 << 56)
            low = np.invert(first, out=t)
            low += _U(1)
            low &= first
            low >>= _U(7)
            low -= _U(1)
            low &= _U(0x1010101010101010)         # "0" - " " in every leading byte
            v -= low
        v += _ZEROS
        out[s:s + _CHUNK] = v
    return out


def int_rows(block: np.ndarray, sep: bytes = b" ") -> bytes | None:
    r"""Lines of the integers of `block` (n, k), fields joined by `sep`, or None when a
    value is negative or has more than 16 digits.

    Each column is right-aligned, with blanks, to the digits of its largest value in the
    block (a few bytes more than ``%d`` at most, for text made a block at a time).

    Examples
    --------
    >>> int_rows(np.array([[1, 20], [300, 4]]), b", ")
    b'  1, 20\n300,  4\n'
    """
    block = np.asarray(block)
    n, k = block.shape
    if len(sep) > 2 or (not sep and k > 1):
        raise ValueError(f"a separator of one or two bytes (none for one column), not {sep!r}")
    if n == 0 or k == 0:
        return b"\n" * n
    if block.dtype.kind not in "iu" or (block.dtype.kind == "i" and block.min() < 0):
        return None
    tops = block.max(axis=0)
    if int(tops.max()) >= 10 ** 16:
        return None
    x = block.astype(np.uint64).ravel()
    if int(tops.max()) < 10 ** 8:
        words = _digits8(x)[:, None]
    else:
        hi = x // _U(10 ** 8)
        lo = x - hi * _U(10 ** 8)
        words = np.empty((len(x), 2), dtype=np.uint64)
        words[:, 0] = _digits8(hi)
        words[:, 1] = _digits8(lo)
        long = hi > 0                    # their low half keeps its zeros
        words[long, 1] = _digits8(lo[long], blank=False)
        words[~long, 0] = _U(0x2020202020202020)   # and the others have no high half
    digits = words.view(np.uint8).reshape(n, k, -1)       # right-aligned, full width
    full = digits.shape[2]
    widths = [len(str(int(t))) for t in tops]
    out = np.empty((n, sum(widths) + len(sep) * (k - 1) + 1), dtype=np.uint8)
    pos = 0
    for c, w in enumerate(widths):
        out[:, pos:pos + w] = digits[:, c, full - w:]
        pos += w
        if c < k - 1:
            out[:, pos:pos + len(sep)] = np.frombuffer(sep, np.uint8)
            pos += len(sep)
    out[:, pos] = ord("\n")
    return out.tobytes()


def sci_rows(ids: np.ndarray, values: np.ndarray, sep: bytes = b", ") -> bytes | None:
    r"""Lines ``<id><sep><value><sep>...`` with every value in scientific notation with 13
    significant digits (as ``%.12e``, the last digit within one unit), or None when a
    value is not finite, or nonzero outside 1e-30 .. 1e30, or an id is not writable by
    :func:`int_rows`.

    Fields are 19 characters: ``-1.234567890123e+05``, a blank for the sign of positive
    values.

    Examples
    --------
    >>> sci_rows(np.array([1]), np.array([[0.5, -1250.0, 0.0]]))
    b'1,  5.000000000000e-01, -1.250000000000e+03,  0.000000000000e+00\n'
    """
    ids = np.asarray(ids).reshape(-1, 1)
    values = np.asarray(values, dtype=np.float64)
    n, k = values.shape
    head = int_rows(ids, b"")
    if head is None or n == 0:
        return None if head is None else b""
    a = np.abs(values).ravel()
    nonzero = a != 0
    if not np.isfinite(a).all() or (nonzero & ((a < 1e-30) | (a >= 1e30))).any():
        return None
    exp = np.zeros(a.shape, dtype=np.int64)
    exp[nonzero] = np.floor(np.log10(a[nonzero])).astype(np.int64)
    mant = _mantissa(a, exp)
    # log10 can land one off next to a power of ten, and rounding can carry to 10**13
    for fix in (mant >= 10 ** 13, (mant < 10 ** 12) & nonzero):
        if fix.any():
            exp[fix] += np.where(mant[fix] >= 10 ** 13, 1, -1)
            mant[fix] = _mantissa(a[fix], exp[fix])
    mant = mant.astype(np.uint64)
    first = mant // _U(10 ** 12)
    rest = mant - first * _U(10 ** 12)
    middle = rest // _U(10 ** 8)
    record = np.dtype([("sep", "u1", (len(sep),)), ("sign", "u1"), ("first", "u1"),
                       ("dot", "u1"), ("middle", "<u4"), ("low", "<u8"), ("e", "u1"),
                       ("esign", "u1"), ("exp", "<u2")])
    out = np.empty(n * k, dtype=record)
    out["sep"] = np.frombuffer(sep, np.uint8)
    out["sign"] = np.where(values.ravel() < 0, ord("-"), ord(" "))
    out["first"] = first.astype(np.uint8) + 0x30
    out["dot"] = ord(".")
    # four digits: the high half of an 8-digit field of `middle` (< 10**4)
    out["middle"] = (_digits8(middle, blank=False) >> _U(32)).astype(np.uint32)
    out["low"] = _digits8(rest - middle * _U(10 ** 8), blank=False)
    out["e"] = ord("e")
    out["esign"] = np.where(exp < 0, ord("-"), ord("+"))
    e = np.abs(exp)
    out["exp"] = ((e // 10) + 0x30) | ((e % 10 + 0x30) << 8)
    line = np.dtype([("id", f"S{len(head) // n - 1}"), ("values", record, (k,)),
                     ("end", "S1")])
    rows = np.empty(n, dtype=line)
    rows["id"] = np.frombuffer(head, dtype=f"S{len(head) // n}")
    rows["values"] = out.reshape(n, k)
    rows["end"] = b"\n"
    return rows.tobytes()


def _mantissa(a: np.ndarray, exp: np.ndarray) -> np.ndarray:
    """round(a / 10**(exp - 12)) as int64, from exact powers of ten (one rounding)."""
    shift = 12 - exp
    up = np.minimum(np.abs(shift), 22)
    scale = _POW10_F[up]
    # 10**k is exact up to k = 22; beyond (|shift| <= 42 here), a second exact power
    rest = _POW10_F[np.clip(np.abs(shift) - 22, 0, 22)]
    m = np.where(shift >= 0, a * scale * rest, a / scale / rest)
    return np.rint(m).astype(np.int64)
