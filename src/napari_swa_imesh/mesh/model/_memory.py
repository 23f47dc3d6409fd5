"""How much memory meshing a label image takes, estimated before any work is done.

The model
---------
A run (read, region tree, balance, template cutting, checks, writing) holds, at its peak,

* a fixed part: the interpreter and libraries, plus the working buffers of the checks,
  which run in chunks of elements and facet keys (``BASE_BYTES``, ``CHECK_BYTES``);
* a part per voxel of the padded grid: the labels themselves (their own dtype), the bool
  and int64 lattices of the mesher (a cumulative vertex numbering, 8 bytes per lattice
  point), and with checks the leaf map (``VOXEL_BYTES``, ``CHECK_VOXEL_BYTES``);
* a part per leaf of the balanced tree (origins, levels, labels, the unbalanced tree
  beside it, the per-leaf site flags; ``LEAF_BYTES``);
* a part per element (vertex ids, leaf, template, quality and angle arrays, material,
  the vertices, meshio's copies when writing and the facet keys of the checks;
  ``ELEMENT_BYTES``).

Leaves and elements are predicted from the number of *boundary voxels* (voxels with a
face neighbour of another label), counted in one chunked O(N) pass: small leaves and
dense elements sit along material boundaries, large Kuhn-cut leaves everywhere else.
The prediction never exceeds the worst case, which depends on the voxel count alone: a
tree has at most one leaf per voxel, and a leaf cut by the templates has at most d! of
its voxels' worth of elements (d! per level-0 leaf; at most 8 per 2^2 pixels in 2-D and
48 per 2^3 voxels in 3-D for larger leaves), so a mesh has at most ``d! * N`` elements.
Without a boundary count the worst case is used.

The constants were fitted to peak RSS (``ru_maxrss`` of a fresh process running
``swa-imesh mesh ... --json``) on brain-like and random-blob uint8 volumes of 64^3 to
256^3 and on a voxel-noise volume, then rounded up so that the estimate lies above every
measured peak (``benchmarks/bench_mesh_memory.py`` repeats the measurement). Refitted
after the streamed writers and chunked checks: 120-140 bytes per element measured at 96^3
and 128^3, refine 0 and 1 (peaks 0.35-0.59 of the estimate on brain and blob volumes;
128^3 refine 1: 3.2 GB against 7.0 GB, where it was 15 GB before and refused).
"""

from __future__ import annotations

import math
import resource

import numpy as np

__all__ = ["available_memory", "count_boundary_voxels", "estimate_mesh_memory"]

#: Interpreter, numpy/scipy/meshio and the reader: resident before the labels arrive.
BASE_BYTES = 150 * 2**20
#: Chunked working buffers of the checks (elements and facet keys in cache-sized chunks).
CHECK_BYTES = 200 * 2**20
#: Per voxel of the padded grid, beyond the labels' own bytes: tree build temporaries,
#: the mesher's bool lattices and its int64 vertex numbering.
VOXEL_BYTES = 16
#: Per voxel, added by the checks: the leaf map (int64 painted, kept as int32).
CHECK_VOXEL_BYTES = 12
#: Per balanced leaf: two trees (origin, level, label), site flags and keys.
LEAF_BYTES = 160
#: Per element while meshing and writing (vertex ids, per-cell data, vertices, the
#: streamed writer's blocks), and added by the checks (sorted ids, facets, volumes).
ELEMENT_BYTES = 150
CHECK_ELEMENT_BYTES = 40  # facet keys (4 x int64), the sort's buffer, volume signs
#: Balanced leaves and elements per boundary voxel, ``a * top_level + b`` (at least 1
#: and d!): every level between the boundary and the roots adds a graded layer, so the
#: ratios grow with the image (brain-like volumes, elements per boundary voxel: 12.5 at
#: 64^3, 17.9 at 128^3, 22.7 at 256^3; leaves 1.2, 1.4, 1.75; random blobs lie below).
LEAVES_PER_BOUNDARY_VOXEL = {2: (0.3, -0.5), 3: (0.3, -0.5)}
ELEMENTS_PER_BOUNDARY_VOXEL = {2: (2.0, -4.0), 3: (5.5, -19.0)}

#: Elements (and leaves) of interface refinement K against K = 0, rounded up from the
#: measured ratios (brain-like and blob volumes, 48^3 to 128^3: 3-D K1 6.2-7.3, K2 37-46;
#: 2-D 512^2 K1 3.0, K2 6.7); beyond K2 the 3-D ratio grows about 6x per level.
REFINE_GROWTH = {2: (1.0, 3.3, 7.5, 16.0, 34.0), 3: (1.0, 7.6, 48.0, 300.0, 1900.0)}

_CHUNK_VOXELS = 1 << 24


def _padded_shape(shape: tuple[int, ...]) -> tuple[int, ...]:
    """Shape of the grid the tree covers: every axis padded to a multiple of the roots."""
    from ..._region_tree import default_top_level

    block = 1 << default_top_level(shape)
    return tuple(-(-n // block) * block for n in shape)


def count_boundary_voxels(labels) -> int:
    """Count voxels that have a face neighbour with a different label.

    Parameters
    ----------
    labels : (M, N[, P, ...]) array_like of int
        Label image (any integer dtype; not copied as a whole).

    Returns
    -------
    int
        Both sides of every interface count, so two touching materials give two voxels
        per face.

    Notes
    -----
    One O(N) pass over slabs of the first axis (about 16 million voxels each), so the
    extra memory is a few bool slabs whatever the image size.

    Examples
    --------
    >>> count_boundary_voxels(np.array([[1, 1, 2], [1, 1, 1]]))
    3
    """
    lab = np.asarray(labels)
    if lab.ndim == 0 or lab.size == 0:
        return 0
    d = lab.ndim
    plane = math.prod(lab.shape[1:])
    step = max(1, _CHUNK_VOXELS // max(1, plane))
    total = 0
    for start in range(0, lab.shape[0], step):
        stop = min(lab.shape[0], start + step)
        lo, hi = max(0, start - 1), min(lab.shape[0], stop + 1)
        block = lab[lo:hi]  # the slab with one plane of context on each side
        mark = np.zeros(block.shape, dtype=bool)
        for a in range(d):
            first = tuple(slice(0, -1) if b == a else slice(None) for b in range(d))
            second = tuple(slice(1, None) if b == a else slice(None) for b in range(d))
            diff = block[first] != block[second]
            mark[first] |= diff
            mark[second] |= diff
        total += int(np.count_nonzero(mark[start - lo:stop - lo]))
    return total


def estimate_mesh_memory(shape, dtype=np.uint8, *, n_boundary: int | None = None,
                         max_label: int | None = None, check: bool = True,
                         cells_per_voxel: tuple[int, ...] | None = None) -> int:
    """Estimate the peak memory (bytes) of meshing a label image with the templates.

    Parameters
    ----------
    shape : tuple of int
        Shape of the label image (2-D or 3-D).
    dtype : dtype, optional
        Its dtype as it is held in memory (floats are converted to int32 first).
    n_boundary : int, optional
        Boundary voxels, from :func:`count_boundary_voxels`; predicts the leaves and
        elements. Default: unknown, so the worst case for the voxel count is used
        (at most one leaf per voxel and d! elements per voxel).
    max_label : int, optional
        The largest label; tells whether unsigned labels need a wider copy for the tree
        (only when their top bit is used). Default: assume they do.
    check : bool
        Whether the mesh checks run too (``check_mesh``; the command line's default).
    cells_per_voxel : tuple of int, optional
        Lattice cells per voxel along each axis (anisotropy subdivision times 2^refine,
        :class:`~._lattice.Lattice`). Subdivision repeats the image onto the lattice (an
        image of that shape with a finer boundary layer); refinement keeps the voxel tree
        and multiplies its leaves and elements by :data:`REFINE_GROWTH`, the dense
        corner lattice by 2^(d K).

    Returns
    -------
    int
        Peak resident memory of the whole run, interpreter included. The model and its
        calibration are described at the top of this module; it is meant to be high
        rather than low (measured peaks lie between 0.5 and 1 times the estimate).

    Examples
    --------
    >>> small = estimate_mesh_memory((64, 64, 64), np.uint8, n_boundary=0)
    >>> worst = estimate_mesh_memory((64, 64, 64), np.uint8)
    >>> small < worst
    True
    """
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    if d not in (2, 3) or min(shape) < 1:
        raise ValueError(f"estimate_mesh_memory needs a 2-D or 3-D shape with at least one "
                         f"voxel per axis; got {shape}.")
    dtype = np.dtype(dtype)
    cells = tuple(int(c) for c in (cells_per_voxel or (1,) * d))
    # cells per voxel = anisotropy factors (the smallest spacing's axis has 1) x 2^refine
    refine = min((c & -c).bit_length() - 1 for c in cells)
    factors = tuple(c >> refine for c in cells)
    if any(f != 1 for f in factors):
        # the image is repeated onto the anisotropy lattice: an image of that shape whose
        # boundary layer is finer (conservative: the labels are counted at that size too)
        factor = math.prod(factors)
        lattice_boundary = (None if n_boundary is None
                            else 2 * int(n_boundary) * factor ** ((d - 1) / d))
        return estimate_mesh_memory(tuple(n * f for n, f in zip(shape, factors)), dtype,
                                    n_boundary=lattice_boundary, max_label=max_label,
                                    check=check, cells_per_voxel=(1 << refine,) * d)
    padded = _padded_shape(shape)
    n_vox, n_pad = math.prod(shape), math.prod(padded)
    # interface refinement splits leaves, it does not repeat the image; but the mesher's
    # corner lattice and the checks' leaf map are dense at the refined resolution
    n_lattice = math.prod((n << refine) + 1 for n in padded)
    n_fine = n_pad << (d * refine)
    label_bytes = n_vox * dtype.itemsize
    if dtype.kind == "f":
        dtype = np.dtype(np.int32)  # whole-valued floats are converted once
        label_bytes += n_vox * dtype.itemsize
    # the tree works on signed labels: unsigned ones are a free view unless the top bit
    # is used (then a copy twice as wide), and on a padded copy unless the shape fits
    widen = dtype.kind in "ub" and (max_label is None
                                    or max_label > 2**(8 * dtype.itemsize - 1) - 1)
    work_item = min(8, 2 * dtype.itemsize) if widen else dtype.itemsize
    work_bytes = (n_pad * work_item if widen else 0) + (n_pad * work_item if n_pad != n_vox else 0)

    worst_leaves = n_pad
    worst_elements = math.factorial(d) * n_pad
    leaves: float
    elements: float
    if n_boundary is None:
        leaves, elements = worst_leaves, worst_elements
    else:
        b = max(0, int(n_boundary))
        top = _top_level(shape)
        roots = max(1, n_pad >> (d * top))  # leaves of a constant image
        (la, lb), (ea, eb) = LEAVES_PER_BOUNDARY_VOXEL[d], ELEMENTS_PER_BOUNDARY_VOXEL[d]
        per_leaf = max(1.0, la * top + lb)
        per_element = max(float(math.factorial(d)), ea * top + eb)
        leaves = min(worst_leaves, per_leaf * b + roots)
        elements = min(worst_elements, per_element * b + math.factorial(d) * roots)
    growth = REFINE_GROWTH[d][refine]
    leaves, elements = leaves * growth, elements * growth
    total = (BASE_BYTES + label_bytes + work_bytes + VOXEL_BYTES * n_lattice
             + LEAF_BYTES * leaves + ELEMENT_BYTES * elements)
    if check:
        total += CHECK_BYTES + CHECK_VOXEL_BYTES * n_fine + CHECK_ELEMENT_BYTES * elements
    return int(math.ceil(total))


def _top_level(shape) -> int:
    from ..._region_tree import default_top_level

    return default_top_level(tuple(shape))


def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _proc_status_bytes(field: str) -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def current_rss() -> int:
    """Resident memory of this process now (bytes; 0 when /proc is not there)."""
    return _proc_status_bytes("VmRSS") or 0


def available_memory() -> int | None:
    """Memory this process can still take, in bytes, or None when nothing says.

    The smallest of: ``MemAvailable`` in ``/proc/meminfo``; a cgroup limit minus the
    cgroup's usage (``/sys/fs/cgroup/memory.max`` in cgroup v2, ``memory.limit_in_bytes``
    in v1); the address-space limit (``RLIMIT_AS``) minus this process's virtual size.
    """
    values = []
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    values.append(int(line.split()[1]) * 1024)
                    break
    except (OSError, ValueError, IndexError):
        pass
    for limit_path, usage_path in (
            ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
            ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
             "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        limit = _read_int(limit_path)  # "max" (no limit) reads as None
        if limit is not None and limit < 2**60:
            values.append(max(0, limit - (_read_int(usage_path) or 0)))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        values.append(max(0, soft - (_proc_status_bytes("VmSize") or 0)))
    return min(values) if values else None


def format_bytes(n: float) -> str:
    """Bytes as a short human figure: ``format_bytes(3 * 2**30)`` is ``'3.0 GB'``."""
    for unit, size in (("TB", 2**40), ("GB", 2**30), ("MB", 2**20), ("kB", 2**10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} bytes"


def parse_memory_size(text: str) -> int | None:
    """Parse ``--memory-limit``: ``auto`` (None), ``off`` (0) or a size such as ``8G``.

    Sizes take an optional K, M, G or T suffix (powers of 1024; a trailing B or iB is
    allowed).

    Examples
    --------
    >>> parse_memory_size("1.5G") == 3 * 2**29
    True
    >>> parse_memory_size("auto") is None, parse_memory_size("off")
    (True, 0)
    """
    t = str(text).strip().lower()
    if t == "auto":
        return None
    if t in ("off", "none", "0"):
        return 0
    for suffix in ("ib", "b"):
        if t.endswith(suffix) and len(t) > len(suffix):
            t = t[:-len(suffix)]
            break
    scale = {"k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}.get(t[-1:], 1)
    number = t[:-1] if scale > 1 else t
    try:
        value = float(number)
    except ValueError:
        value = -1.0
    if not (math.isfinite(value) and value > 0):
        raise ValueError(
            f"--memory-limit takes auto, off, or a size in bytes with an optional K, M, G "
            f"or T suffix, such as 8G; got {text!r}."
        )
    return int(value * scale)
