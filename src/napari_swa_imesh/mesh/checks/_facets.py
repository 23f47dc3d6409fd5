"""Named facet groups of a mesh: the faces boundary conditions are put on.

Facets are the (d-1)-faces of the simplices: edges in 2-D, triangles in 3-D. Each
boundary facet and each facet between two materials belongs to exactly one group:

* ``xmin, xmax, ymin, ymax[, zmin, zmax]``: boundary facets on a side of the image box
  (x = column, y = row, z = plane, the axes of the mesh files);
* ``interface_<A>_<B>``: facets between meshed materials A and B, A the lower label;
* ``exterior_<A>``: boundary facets of material A away from the box (where A meets a
  material left out of the mesh).

Material names are those of the material groups (``material_<id>`` without a name).

Two ways to the same groups: a mesh the template mesher made is read leaf by leaf
(``_leaf_facets``: no sort, a few times faster at volume size); any other mesh pairs
every facet occurrence by one sort of integer keys (below, shared with the checks).
Tests compare the two on random label images.
"""

from __future__ import annotations

import numpy as np

from ..formats._common import FACE_CORNERS
from ..model._types import Mesh
from ._groups import FacetGroup, named_groups
from ._leaf_facets import template_group_rows

__all__ = ["FacetGroup", "facet_groups", "paired_facets", "FACE_CORNERS"]



def paired_facets(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every distinct facet of a simplex mesh once, with the one or two elements it bounds.

    Parameters
    ----------
    cells : (M, d+1) ndarray of int
        Positively oriented triangles or tetrahedra.

    Returns
    -------
    facets : (G, d) ndarray of intp
        Oriented out of its first owner, in the lexicographic order of the facets' sorted
        vertex ids.
    owners : (G, 2) ndarray of intp
        The elements on either side (the lower element index first); the second is -1 on
        the boundary (and for a facet of three or more elements, which has no pair).
    opposite : (G, 2) ndarray of intp
        Each owner's corner opposite the facet (-1 where there is no second owner).

    Examples
    --------
    >>> facets, owners, opposite = paired_facets(np.array([[0, 1, 2], [1, 3, 2]]))
    >>> owners.tolist()
    [[0, -1], [0, -1], [0, 1], [1, -1], [1, -1]]
    """
    cells = np.asarray(cells, dtype=np.intp)
    return _paired_result(cells, *_pair_rows(cells))


def _paired_result(cells: np.ndarray, one: np.ndarray, two: np.ndarray):
    """(facets, owners, opposite) of :func:`paired_facets` from the face rows of the owners."""
    d = cells.shape[1] - 1
    shared = two >= 0
    owners = np.stack([one // (d + 1), np.where(shared, two // (d + 1), -1)], axis=1)
    opposite = np.stack([one % (d + 1), np.where(shared, two % (d + 1), -1)], axis=1)
    return cells[owners[:, 0, None], FACE_CORNERS[d][opposite[:, 0]]], owners, opposite


def _pair_rows(cells: np.ndarray, keep_pair=None) -> tuple[np.ndarray, np.ndarray]:
    """Face rows (``cell * (d+1) + corner``) of each facet's first and second owner.

    Facets come in the lexicographic order of their sorted vertex ids; `two` is -1 where a
    facet has one owner or three and more. ``keep_pair(first, second)`` (face rows),
    when given, says which two-owner facets to keep; single ones are always kept.
    """
    one, two = [], []
    for keys, rows, _ in _facet_passes(cells):
        starts, counts = _runs(keys, rows.bit_length)
        first = rows.rows[keys[starts] & rows.mask]
        pair = counts == 2
        second = np.full(len(starts), -1, dtype=np.intp)
        second[pair] = rows.rows[keys[starts[pair] + 1] & rows.mask]
        if keep_pair is not None:
            keep = ~pair
            keep[pair] = keep_pair(first[pair], second[pair])
            first, second = first[keep], second[keep]
        one.append(first)
        two.append(second)
    if not one:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    return np.concatenate(one), np.concatenate(two)


# ----------------------------------------------------------------------------- facet keys
# Every facet occurrence (cell, corner) becomes one int64 key: its sorted vertex ids
# a < b (< c) packed as (a - lo, b - a, c - a) above `tail` low bits (the side it is seen
# from, or its row in the pass). Equal facets get equal codes and one np.sort of plain
# integers (far faster than lexsort or argsort) puts copies side by side. When the keys
# do not fit 64 bits, facets are handled in passes over ranges of their lowest id.

_KEYS_PER_PASS = 1 << 27          # keys sorted at once (8 bytes each)
_CHUNK = 1 << 16                  # cells turned into keys at once
_RUN_BLOCK = 1 << 18              # sorted keys scanned for runs at once
_MAX_PASSES = 1 << 12             # beyond this, a pass sorts rows of ids instead


def _sorted_facet(cols: list) -> tuple[list, np.ndarray]:
    """The d columns of facets sorted per row (d = 2, 3), and whether the sort was odd."""
    if len(cols) == 2:
        x, y = cols
        return [np.minimum(x, y), np.maximum(x, y)], x > y
    x, y, z = cols
    lo = np.minimum(np.minimum(x, y), z)
    hi = np.maximum(np.maximum(x, y), z)
    return [lo, x ^ y ^ z ^ lo ^ hi, hi], (x > y) ^ (x > z) ^ (y > z)


def _sorted_cell(cols: list) -> tuple[list, np.ndarray]:
    """The columns of cells sorted per row by a sorting network, and the parity of the
    permutation (each exchange that swaps flips it)."""
    cols = list(cols)
    odd = np.zeros(len(cols[0]), dtype=bool)
    pairs = {3: ((0, 1), (1, 2), (0, 1)), 4: ((0, 1), (2, 3), (0, 2), (1, 3), (1, 2))}
    for i, j in pairs[len(cols)]:
        swap = cols[i] > cols[j]
        odd ^= swap
        cols[i], cols[j] = np.minimum(cols[i], cols[j]), np.maximum(cols[i], cols[j])
    return cols, odd


def _lowest(cols: list) -> np.ndarray:
    out = np.minimum(cols[0], cols[1])
    for c in cols[2:]:
        np.minimum(out, c, out=out)
    return out


def _spread_bits(cells: np.ndarray) -> int:
    """Bits of the largest id difference inside one cell (bounds b - a and c - a)."""
    spread = 0
    for start in range(0, len(cells), _CHUNK << 2):
        cols = [cells[start:start + (_CHUNK << 2), j] for j in range(cells.shape[1])]
        # column by column: numpy's reductions along a short row axis are slow
        hi, lo = np.maximum(cols[0], cols[1]), np.minimum(cols[0], cols[1])
        for c in cols[2:]:
            np.maximum(hi, c, out=hi)
            np.minimum(lo, c, out=lo)
        hi -= lo
        spread = max(spread, int(hi.max()))
    return max(1, spread.bit_length())


def _windows(per_vertex: np.ndarray, span: int, cap: int,
             limit: int | None = None) -> np.ndarray | None:
    """Bounds of vertex ranges of at most `span` ids and `cap` occurrences (greedy), or
    None past `limit` ranges."""
    n = len(per_vertex)
    cum = np.concatenate([[0], np.cumsum(per_vertex)])
    bounds = [0]
    while bounds[-1] < n:
        b = bounds[-1]
        e = min(b + span, int(np.searchsorted(cum, cum[b] + cap, side="right")) - 1, n)
        bounds.append(max(e, b + 1))
        if limit is not None and len(bounds) > limit + 1:
            return None
    return np.asarray(bounds, dtype=np.int64)


class _Packer:
    """Keys of one pass: (a - lo, b - a[, c - a]) in `w`-bit fields above `tail` bits."""

    def __init__(self, w: int, tail: int, lo: int):
        self.w, self.tail, self.lo = w, tail, lo

    def encode(self, cols: list, low_bits: np.ndarray, out: np.ndarray | None = None
               ) -> np.ndarray:
        """int64 keys (the caller keeps them below 2**63) of sorted facet columns, into
        `out` when given."""
        key = np.subtract(cols[0], self.lo, out=out, dtype=np.int64)
        for c in cols[1:]:
            key <<= self.w
            key |= c - cols[0]
        key <<= self.tail
        key |= low_bits
        return key

    def coefficients(self, d: int) -> list[int]:
        """Multipliers of the d sorted ids (less `lo`) whose sum is the key less its low
        bits, e.g. ``[2**(2w+t) - 2**(w+t) - 2**t, 2**(w+t), 2**t]`` in 3-D."""
        places = [1 << (self.tail + self.w * (d - 1 - q)) for q in range(d)]
        return [places[0] - sum(places[1:]), *places[1:]]

    def decode(self, keys: np.ndarray, d: int) -> list:
        """Sorted vertex ids (d int64 columns) of the facets of `keys`."""
        code = keys >> self.tail
        a = (code >> ((d - 1) * self.w)) + self.lo
        return [a, *[((code >> (self.w * j)) & ((1 << self.w) - 1)) + a
                     for j in range(d - 2, -1, -1)]]


class _Ranked:
    """Keys of one pass made from the facets' rank among the sorted rows (ids too wide)."""

    def __init__(self, cols: list, low_bits: np.ndarray, tail: int):
        order = np.lexsort((low_bits, *cols[::-1]))
        self.cols = [c[order] for c in cols]
        new = np.ones(len(order), dtype=bool)
        new[1:] = np.any([c[1:] != c[:-1] for c in self.cols], axis=0)
        self.first = np.flatnonzero(new)
        self.tail = tail
        self.keys = ((np.cumsum(new) - 1) << tail) | low_bits[order]

    def decode(self, keys: np.ndarray, d: int) -> list:
        at = self.first[keys >> self.tail]
        return [c[at].astype(np.int64) for c in self.cols]


def _runs(keys: np.ndarray, tail: int) -> tuple[np.ndarray, np.ndarray]:
    """Start and length of each run of equal facets in sorted `keys`."""
    code = keys >> tail
    new = np.ones(len(code), dtype=bool)
    np.not_equal(code[1:], code[:-1], out=new[1:])
    starts = np.flatnonzero(new)
    counts = np.empty(len(starts), dtype=np.int64)
    counts[:-1] = starts[1:] - starts[:-1]
    counts[-1:] = len(keys) - starts[-1:]
    return starts, counts


def _blocks(keys: np.ndarray, tail: int, size: int = _RUN_BLOCK):
    """Slices of about `size` sorted keys that never split a run of equal facets (small
    pieces stay in cache, and no temporary is as long as all the keys)."""
    start, n = 0, len(keys)
    while start < n:
        end = min(start + size, n)
        while end < n and keys[end] >> tail == keys[end - 1] >> tail:
            end += 1
        yield slice(start, end)
        start = end


def _side_passes(cells: np.ndarray, sign: np.ndarray, spread_bits: int,
                 max_keys: int | None = None, n_points: int | None = None):
    """Sorted keys of every facet occurrence with the side it is seen from as the low bit.

    `sign` (M,) is the sign of each cell's volume and `spread_bits` the bits of the
    largest id difference within a cell. The bit is 1 when the cell lies on the positive
    side of its facet taken in sorted order (a flat cell counts as negative), so a facet
    shared from opposite sides is one key ending in 0 followed by the same key ending in 1.
    Keys are built from chunks of cells straight into the pass's array. `n_points`, when
    given, bounds the ids (else one pass over the cells finds it). Yields (keys, packer)
    per pass.
    """
    m, n_vert = cells.shape
    d = n_vert - 1
    cap = max_keys or _KEYS_PER_PASS
    if n_points is None:
        n_points = int(cells.max()) + 1 if m else 1
    dtype = np.int32 if n_points < 2**31 else np.int64

    def chunks():
        for start in range(0, m, _CHUNK):
            chunk = cells[start:start + _CHUNK].astype(dtype)
            ids, odd = _sorted_cell([chunk[:, j] for j in range(n_vert)])
            del chunk
            s = sign[start:start + _CHUNK]
            # det of the sorted cell has sign s * (-1)^odd; the cell lies on side
            # det * (-1)^(d-i) of its facet without sorted corner i (ids still sorted)
            positive = [np.where(odd, s < 0, s > 0), np.where(odd, s > 0, s < 0)]
            for i in range(n_vert):
                yield ids[:i] + ids[i + 1:], positive[(d - i) % 2]

    span_bits = 62 - (d - 1) * spread_bits       # bits left for a - lo (int64 keys)
    ranked = span_bits < 1
    if m * n_vert <= cap and (ranked or n_points <= 1 << span_bits):
        bounds, sizes = [0, n_points], [m * n_vert]
    else:  # count facets per block of lowest ids, then cut passes at block edges
        shift = max(0, n_points.bit_length() - 16)
        shift = shift if ranked else min(shift, span_bits)
        per_block = np.zeros((n_points >> shift) + 1, dtype=np.int64)
        for cols, _ in chunks():
            per_block += np.bincount(cols[0] >> shift, minlength=len(per_block))
        blocks = None if ranked else _windows(per_block, 1 << (span_bits - shift), cap,
                                              _MAX_PASSES)
        if blocks is None:  # ids too far apart to pack: rank sorted rows instead
            ranked = True
            blocks = _windows(per_block, len(per_block), cap)
        bounds = (blocks << shift).tolist()
        sizes = np.add.reduceat(per_block, blocks[:-1]).tolist()
    for p, size in enumerate(sizes):
        lo, hi = bounds[p], bounds[p + 1]
        packer = _Packer(spread_bits, 1, lo)
        keys, parts = (None, []) if ranked else (np.empty(size, dtype=np.int64), None)
        at = 0
        if not ranked and len(sizes) == 1:
            _fill_linear(keys, cells, sign, packer)
        for cols, bits in (() if keys is not None and len(sizes) == 1 else chunks()):
            if len(sizes) > 1:
                sel = (cols[0] >= lo) & (cols[0] < hi)
                cols, bits = [c[sel] for c in cols], bits[sel]
            if ranked:
                parts.append((cols, bits))
            else:
                packer.encode(cols, bits, out=keys[at:at + len(bits)])
            at += len(bits)
        if ranked:
            packer = _Ranked([np.concatenate([c[j] for c, _ in parts]) for j in range(d)],
                             np.concatenate([b for _, b in parts]), 1)
            keys = packer.keys
        else:
            # equal keys are equal integers, so any sort gives the same array: numpy's
            # default (SIMD quicksort) beat timsort on these keys
            keys.sort()
        yield keys, packer


def _fill_linear(keys: np.ndarray, cells: np.ndarray, sign: np.ndarray, packer) -> None:
    """The keys of :func:`_side_passes` for one pass from id 0, as a linear form.

    The fields of a key do not overlap, so ``((a << w | b - a) << w | c - a) << 1 | bit``
    is ``A a + B b + C c + bit`` (A, B, C from :meth:`_Packer.coefficients`): each sorted
    id times the coefficients of the places it takes in a cell's facets (two at most),
    then d - 1 additions per key, instead of shifting and masking every key.
    """
    m, n_vert = cells.shape
    d = n_vert - 1
    coef = packer.coefficients(d)
    for start in range(0, m, _CHUNK):
        ids, odd = _sorted_cell([cells[start:start + _CHUNK, j].astype(np.int64, copy=False)
                                 for j in range(n_vert)])
        n = len(odd)
        s = sign[start:start + _CHUNK]
        positive = [np.where(odd, s < 0, s > 0), np.where(odd, s > 0, s < 0)]
        # sorted id j sits at place j in the facets without a later corner, j - 1 after
        term = {(j, q): ids[j] * coef[q] for j in range(n_vert) for q in (j - 1, j)
                if 0 <= q < d}
        for i in range(n_vert):
            out = keys[start * n_vert + i * n:start * n_vert + (i + 1) * n]
            places = [(j, j if j < i else j - 1) for j in range(n_vert) if j != i]
            np.add(term[places[0]], term[places[1]], out=out)
            for place in places[2:]:
                out += term[place]
            out += positive[(d - i) % 2]


class _PassRows:
    """Face rows of a pass's occurrences, indexed by the low `bit_length` bits of a key."""

    def __init__(self, rows: np.ndarray, bit_length: int):
        self.rows, self.bit_length = rows, bit_length
        self.mask = (1 << bit_length) - 1


def _facet_passes(cells: np.ndarray):
    """Sorted keys of every facet occurrence with its row in the pass as the low bits.

    Among equal facets the lower face row (``cell * (d+1) + corner``) comes first, as a
    stable sort would give. Yields (keys, _PassRows, packer) per pass, passes in
    increasing lowest id.
    """
    m, n_vert = cells.shape
    d = n_vert - 1
    if m == 0:
        return
    n_points = int(cells.max()) + 1
    flat = cells.reshape(-1)
    columns = [cells[:, j] for j in range(n_vert)]
    low = np.stack([_lowest([columns[j] for j in FACE_CORNERS[d][k]]) for k in range(n_vert)],
                   axis=1).reshape(-1)                      # (M(d+1),) lowest id per face row
    per_vertex = np.bincount(low, minlength=n_points)
    w = _spread_bits(cells)
    total = m * n_vert
    # widest id range per pass such that the rows of a pass still fit beside the codes
    best = None
    for span_bits in range(max(1, n_points.bit_length()), 0, -1):
        row_bits = 63 - (d - 1) * w - span_bits
        if row_bits < 1:
            continue
        cap = min(_KEYS_PER_PASS, 1 << row_bits)
        guess = max(-(-n_points >> span_bits), -(-total // cap))
        if best is None or guess < best[0]:
            best = (guess, span_bits, cap)
    bounds = None
    if best is not None and best[0] <= _MAX_PASSES:
        bounds = _windows(per_vertex, 1 << best[1], best[2], _MAX_PASSES)
    ranked = bounds is None
    if ranked:
        bounds = _windows(per_vertex, n_points, _KEYS_PER_PASS)
    n_pass = len(bounds) - 1
    vertex_pass = np.repeat(np.arange(n_pass, dtype=np.uint16 if n_pass < 1 << 16
                                      else np.uint32), np.diff(bounds))
    face_pass = vertex_pass[low]
    del low
    # counting sort of the face rows by pass (radix sort for 16-bit ids), stable
    order = np.argsort(face_pass, kind="stable") if n_pass > 1 else np.arange(total)
    ends = np.cumsum(np.bincount(face_pass, minlength=n_pass))
    del face_pass
    corners = FACE_CORNERS[d]
    for p in range(n_pass):
        rows = order[(ends[p - 1] if p else 0):ends[p]]
        cell, corner = rows // n_vert * n_vert, rows % n_vert
        cols, _ = _sorted_facet([flat[cell + corners[corner, j]] for j in range(d)])
        del cell, corner
        local = np.arange(len(rows))
        if ranked:
            packer = _Ranked(cols, local, max(1, (len(rows) - 1).bit_length()))
            keys = packer.keys
        else:
            packer = _Packer(w, max(1, (len(rows) - 1).bit_length()), int(bounds[p]))
            keys = packer.encode(cols, local)
            keys.sort()  # rows make every key distinct: any sort gives one order
        yield keys, _PassRows(rows, packer.tail), packer


def facet_groups(mesh: Mesh) -> dict[str, FacetGroup]:
    """Every boundary facet and every material interface of `mesh`, in named groups.

    Parameters
    ----------
    mesh : Mesh
        Positively oriented triangles or tetrahedra (the mesher's and ``read_mesh``'s
        convention).

    Returns
    -------
    dict of str to FacetGroup
        Groups in the order box sides, interfaces, exteriors; empty groups left out.

    Examples
    --------
    >>> import numpy as np
    >>> from napari_swa_imesh.mesh import mesh_labels
    >>> groups = facet_groups(mesh_labels(np.array([[1, 2]])))
    >>> {name: len(g) for name, g in groups.items()}
    {'xmin': 1, 'xmax': 1, 'ymin': 2, 'ymax': 2, 'interface_material_1_material_2': 1}
    """
    return groups_and_signs(mesh)[0]


def groups_and_signs(mesh: Mesh, signs: bool = False, facets: bool = True):
    """:func:`facet_groups`, and with `signs` which elements have a negative volume in
    the points' frame when the leaf path found it on the way (else None). Without
    `facets`, the groups' ``facets`` are None (owner and corner only)."""
    cells = np.asarray(mesh.cells, dtype=np.intp)
    material = np.asarray(mesh.material)
    fast = template_group_rows(mesh, signs=signs)
    if fast is None:
        return _sorted_groups(mesh), None
    owner, opposite, across = fast[:3]
    order = _lexicographic(cells, owner, opposite)
    owner, opposite, across = owner[order], opposite[order], across[order]
    boundary = across < 0
    return named_groups(mesh, cells, material, owner[boundary], opposite[boundary],
                        owner[~boundary], opposite[~boundary],
                        across[~boundary], facets), (fast[3] if signs else None)


def _sorted_groups(mesh: Mesh) -> dict[str, FacetGroup]:
    """:func:`facet_groups` for any mesh: every facet occurrence paired by one sort."""
    d = mesh.ndim
    cells = np.asarray(mesh.cells, dtype=np.intp)
    material = np.asarray(mesh.material)
    # the pairs inside one material name no group: dropped pass by pass, never stored
    _, owners, opposite = _paired_result(cells, *_pair_rows(
        cells, lambda one, two: material[one // (d + 1)] != material[two // (d + 1)]))
    boundary = owners[:, 1] < 0
    shared = np.flatnonzero(~boundary)
    # each interface facet as seen from material A, the lower label
    ma, mb = material[owners[shared, 0]], material[owners[shared, 1]]
    side = (ma > mb).astype(np.intp)
    return named_groups(mesh, cells, material, owners[boundary, 0], opposite[boundary, 0],
                         owners[shared, side], opposite[shared, side],
                         np.maximum(ma, mb))


def _lexicographic(cells: np.ndarray, owner: np.ndarray, opposite: np.ndarray) -> np.ndarray:
    """Order of facets by their sorted vertex ids (the order of :func:`paired_facets`)."""
    d = cells.shape[1] - 1
    corners = FACE_CORNERS[d][opposite]
    cols, _ = _sorted_facet([cells[owner, corners[:, j]] for j in range(d)])
    return np.lexsort(cols[::-1])
