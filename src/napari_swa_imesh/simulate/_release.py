"""Give the freed heap back to the system between the phases of a large solve.

numpy's vectors of a few MB (the assembly's chunks and batches, the multigrid's set-up)
come from glibc's heap, and freeing them leaves the pages resident until the top of the
heap is free: the next phase then counts them on top of its own peak. ``malloc_trim(0)``
returns every free page of the heap to the system. Where the C library has no
``malloc_trim`` (musl, macOS, Windows) this is a no-op.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["release_memory"]

_TRIM: list = []          # [the C function, or None where there is none], looked up once


def _trim_function():
    if not _TRIM:
        function = None
        try:
            name = ctypes.util.find_library("c")
            libc = ctypes.CDLL(name) if name else ctypes.CDLL(None)
            function = getattr(libc, "malloc_trim", None)
            if function is not None:
                function.argtypes = [ctypes.c_size_t]
                function.restype = ctypes.c_int
        except (OSError, AttributeError, TypeError):
            function = None
        _TRIM.append(function)
    return _TRIM[0]


def release_memory() -> bool:
    """Return the free pages of the C heap to the system; never raises.

    Returns
    -------
    bool
        Whether anything could be asked of the C library (``malloc_trim`` exists).

    Examples
    --------
    >>> release_memory() in (True, False)
    True
    """
    function = _trim_function()
    if function is None:
        return False
    try:
        function(0)
    except (OSError, ctypes.ArgumentError):
        return False
    return True
