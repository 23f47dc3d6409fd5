"""A piece's checks and facet groups, from the template tables instead of its points.

Every element of a piece is a scaled copy of a template (``_templates_luts.TEMPLATES``,
corners in the element's order, in units of its leaf's side), so which of its facets lie
on a face of its leaf, and where the lattice cell just across that face is, are table
look-ups: no comparison of coordinates and no sort of facets.

* Groups and seams: only leaves with a voxel next to another label, the image box or the
  block's box can hold a group or seam facet (a summed-area table of those voxels, read
  at each leaf's corners); only their elements' leaf-face facets are probed, once each.
* Conformity: the chain ``∂(sum of elements)`` (``checks._chain_check``'s argument): every
  element facet enters with its outward orientation as the product of fixed pseudo-random
  values of its vertices' global ids, signed by the parity of their order; less the
  facets allowed to stay single (box sides, exteriors, seams) it must vanish modulo
  2**64. A hanging vertex, a hole or a facet seen twice from one side leaves a remainder
  (zero by chance with probability about 2**-60).
* Volumes: ``d!`` times each element's signed volume from its integer corners (exact),
  summed per material; every one must be positive.
"""

from __future__ import annotations

import functools

import numpy as np

from ..._region_tree import PAD_LABEL
from ..formats._common import FACE_CORNERS
from ..mesher import _templates_luts as luts
from ..mesher._packed import unpack
from ..model._quality import _edge_det

__all__ = ["face_tables", "facet_chain", "outward_facets", "piece_pass", "probe_facets",
           "vertex_values"]

_CHUNK = 1 << 17            # elements per pass of the volume and chain loops
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@functools.cache
def face_tables(d: int) -> tuple[np.ndarray, np.ndarray]:
    """Per template and facet (opposite corner k): the leaf face it lies on as a bit
    number ``2 * axis + (0 low, 1 high)`` or -1 (inside the leaf), and twice its lowest
    corner in units of the leaf side, ((T, d+1) int8, (T, d+1, d) int64)."""
    tpl = np.rint(2 * luts.TEMPLATES[d]).astype(np.int64)           # halves of the side
    on_face = np.full(tpl.shape[:2], -1, np.int8)
    low = np.zeros(tpl.shape[:2] + (d,), np.int64)
    for k in range(d + 1):
        corners = tpl[:, FACE_CORNERS[d][k]]                         # (T, d, d)
        low[:, k] = corners.min(axis=1)
        for a in range(d):
            for side, value in ((0, 0), (1, 2)):
                on_face[(corners[:, :, a] == value).all(axis=1), k] = 2 * a + side
    return on_face, low


def vertex_values(gid: np.ndarray) -> np.ndarray:
    """A fixed pseudo-random 64-bit value per global vertex id (splitmix64), the same in
    every piece."""
    z = gid.astype(np.uint64) + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def _odd(ids: list) -> np.ndarray:
    """Parity of the order of 2 or 3 id columns (True: an odd permutation of sorted)."""
    if len(ids) == 2:
        return ids[0] > ids[1]
    return (ids[0] > ids[1]) ^ (ids[0] > ids[2]) ^ (ids[1] > ids[2])


def _signed_sum(terms: np.ndarray, odd: np.ndarray) -> int:
    """Sum of ``terms`` with the odd ones negated, modulo 2**64."""
    return (int(terms.sum(dtype=np.uint64))
            - 2 * int(np.dot(terms, odd.astype(np.uint64)))) & ((1 << 64) - 1)


def facet_chain(cells_rows: np.ndarray, values: np.ndarray) -> int:
    """The chain of the outward facets `cells_rows` ((F, d) vertex numbers in outward
    order), modulo 2**64."""
    if not len(cells_rows):
        return 0
    cols = [np.ascontiguousarray(cells_rows[:, j]) for j in range(cells_rows.shape[1])]
    prod = values[cols[0]]
    for c in cols[1:]:
        prod = prod * values[c]
    return _signed_sum(prod, _odd(cols))


def piece_pass(packed: tuple[np.ndarray, int], cells: np.ndarray, values: np.ndarray,
               leaf_of: np.ndarray, n_leaves: int, longest: int) -> tuple[np.ndarray, int, int]:
    """One pass over the elements: ``d!`` times the volume per leaf ((n_leaves,) int64,
    exact), the number of elements without a positive volume, and the chain of every
    element facet (outward) modulo 2**64.

    `packed` is the points packed (``_packed.pack_points``: integer, non-negative), one
    gather per corner bringing its coordinates and its value `values` side by side.
    `longest` bounds the elements' edges (their leaves' side): up to 2**9 the
    determinants are exact in int32 (six products below 2**27).
    """
    code, bits = packed
    d = cells.shape[1] - 1
    pairs = np.empty((len(code), 2), np.int64)
    pairs[:, 0] = code
    pairs[:, 1] = values.view(np.int64)
    both = pairs.view(np.complex128).reshape(-1)     # one 16-byte item per point: a gather
    per_leaf = np.zeros(n_leaves, np.float64)
    bad = chain = 0
    for start in range(0, len(cells), _CHUNK):
        col = np.ascontiguousarray(cells[start:start + _CHUNK].T)      # (d+1, n)
        got = both[col].view(np.int64)                                 # corner, value, ...
        p = unpack(got[:, 0::2], bits, d, np.int32 if longest <= 1 << 9 else np.int64)
        det = _edge_det([[p[k][a] - p[0][a] for a in range(d)] for k in range(1, d + 1)])
        del p
        bad += int(np.count_nonzero(det <= 0))
        # float weights are exact: each leaf's sum is an integer far below 2**53
        per_leaf += np.bincount(leaf_of[start:start + _CHUNK], weights=det,
                                minlength=n_leaves)
        v = got[:, 1::2].view(np.uint64)
        for k in range(d + 1):
            f = FACE_CORNERS[d][k]
            prod = v[f[0]] * v[f[1]]
            for j in f[2:]:
                prod *= v[j]
            chain += _signed_sum(prod, _odd([col[j] for j in f]))
    return np.rint(per_leaf).astype(np.int64), bad, chain & ((1 << 64) - 1)


def _flagged_leaves(win: np.ndarray, origin: np.ndarray, level: np.ndarray,
                    lo: np.ndarray) -> np.ndarray:
    """Which leaves (all inside the block) hold a voxel with a face neighbour of another
    label (the window's halo included, padding outside the image) or on the block's box."""
    d = win.ndim
    core = (slice(1, -1),) * d
    centre = win[core]
    edge = np.zeros(centre.shape, bool)
    for a in range(d):
        for step in (0, 2):
            nb = tuple(slice(step, step + n) if b == a else slice(1, -1)
                       for b, n in enumerate(centre.shape))
            edge |= centre != win[nb]
        edge[(slice(None),) * a + (0,)] = True
        edge[(slice(None),) * a + (-1,)] = True
    table = np.zeros(tuple(n + 1 for n in centre.shape), np.int32)
    table[(slice(1, None),) * d] = edge
    del edge
    for a in range(d):
        np.cumsum(table, axis=a, out=table)
    o = origin - lo
    far = o + (np.int64(1) << level.astype(np.int64))[:, None]
    count = np.zeros(len(origin), np.int64)
    for corner in range(1 << d):
        ends = tuple(far[:, a] if corner >> a & 1 else o[:, a] for a in range(d))
        sign = -1 if (d - bin(corner).count("1")) & 1 else 1
        count += sign * table[ends]
    return count > 0


def probe_facets(win: np.ndarray, lo: np.ndarray, hi: np.ndarray, shape, cells: np.ndarray,
                 template_id: np.ndarray, leaf_of: np.ndarray, origin: np.ndarray,
                 level: np.ndarray, label: np.ndarray, meshed: np.ndarray):
    """The leaf-face facets that may bound a group or a seam, and what lies across them.

    Parameters
    ----------
    win : ndarray
        The block's window (one voxel of halo, ``PAD_LABEL`` outside the image).
    lo, hi : (d,) ndarray of int64
        The block's box.
    shape : tuple of int
        The image's shape.
    cells, template_id, leaf_of : ndarray
        The piece's elements, their templates and leaves (indices into the next three).
    origin, level, label : ndarray
        The leaves near the block.
    meshed : (L,) ndarray of bool
        The leaves the piece meshes (all inside the block).

    Returns
    -------
    owner, corner, axis, out : (F,) ndarray
        The element, its corner opposite the facet, the axis of the leaf face and its
        outward sign (-1, 1).
    value : (F,) ndarray of int64
        The label across (``PAD_LABEL`` outside the image).
    inside_image, in_block : (F,) ndarray of bool
        Whether the voxel across lies in the image, in the block.

    Facets whose voxel across is in the block and holds the element's own label are left
    out (they bound nothing).
    """
    d = win.ndim
    on_face, low2 = face_tables(d)
    flag = np.zeros(len(origin), bool)
    leaves = np.flatnonzero(meshed)
    flag[leaves] = _flagged_leaves(win, origin[leaves], level[leaves], lo)
    elems = np.flatnonzero(flag[leaf_of])
    tid = template_id[elems]
    face = on_face[tid]                                              # (n, d+1)
    row, corner = np.nonzero(face >= 0)
    owner = elems[row]
    tk = tid[row].astype(np.intp) * (d + 1) + corner                 # (template, facet)
    del face, row, elems, tid
    # the flat window key of the voxel across: the leaf's lowest voxel, plus per
    # (template, facet) a multiple of half the leaf's side and a constant step out
    wstrides = np.array([int(np.prod(win.shape[a + 1:])) for a in range(d)], np.int64)
    bit = on_face.reshape(-1).astype(np.int64)
    axis_t, high_t = np.maximum(bit, 0) >> 1, (bit & 1).astype(bool)
    low2 = low2.reshape(-1, d).copy()
    rows_t = np.arange(len(bit))
    low2[rows_t, axis_t] = np.where(high_t, 2, 0)
    per_side = low2 @ wstrides                        # times half the side
    step = np.where(high_t | (bit < 0), 0, -wstrides[axis_t])
    lf = leaf_of[owner]
    side = np.int64(1) << level.astype(np.int64)                    # (L,)
    okey = (origin - (lo - 1)) @ wstrides                            # (L,)
    value = win.reshape(-1)[okey[lf] + ((per_side[tk] * side[lf]) >> 1) + step[tk]]
    # faces of each leaf on the block's box: the voxel across them is another block's
    on_box = np.zeros(len(origin), np.int64)
    for a in range(d):
        on_box |= (origin[:, a] == lo[a]).astype(np.int64) << (2 * a)
        on_box |= (origin[:, a] + side == hi[a]).astype(np.int64) << (2 * a + 1)
    in_block = ((on_box[lf] >> bit[tk]) & 1) == 0
    keep = np.flatnonzero(~in_block | (value != label[lf]))
    owner, tk, value, in_block = owner[keep], tk[keep], value[keep], in_block[keep]
    return (owner, tk % (d + 1), axis_t[tk], np.where(high_t[tk], 1, -1), value,
            value != PAD_LABEL, in_block)


def outward_facets(cells: np.ndarray, owner: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """(F, d) vertex numbers of the facets opposite `corner` of `owner`, outward."""
    d = cells.shape[1] - 1
    return cells[owner[:, None], FACE_CORNERS[d][corner]]

