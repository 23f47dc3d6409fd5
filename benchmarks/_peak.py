"""A child process's own peak resident memory, as source for the children's scripts.

The benchmarks run each case in a fresh interpreter (``python -c CHILD``) so that its peak
is its own. ``ru_maxrss`` is not: Linux carries the parent's resident high-water mark at
fork into the child's ``ru_maxrss`` across exec (a child of an 845 MB process reported
845 MB against 104 MB of its own). ``VmHWM`` in ``/proc/self/status`` belongs to the new
image alone; where there is no ``/proc`` (macOS) ``ru_maxrss`` is the fallback, in bytes
on macOS and KiB elsewhere.
"""

from __future__ import annotations

__all__ = ["PEAK_SOURCE"]

#: Defines ``peak_bytes()`` in the child; prepend it to the child's own source.
PEAK_SOURCE = '''
def peak_bytes():
    """This process's own peak resident set size in bytes."""
    import resource, sys
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss if sys.platform == "darwin" else rss * 1024
'''
