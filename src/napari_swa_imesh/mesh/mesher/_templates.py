"""The template (dictionary) mesher: every balanced leaf cut by look-up tables.

Each leaf is cut according to which of its edge midpoints and face centres are vertices
(``_templates_luts.py`` holds the tables and their conventions). Everything is integer
arithmetic on the lattice of pixel corners of the padded grid: a point is its lattice
key ``coords @ strides``; leaf centres and new face centres of leaves of level >= 1 are
lattice points too (level-0 leaves never carry sites), so vertices are deduplicated by
their keys and no floating-point predicate is evaluated. Every element is a scaled copy
of a template, so its quality is a table look-up.
"""

from __future__ import annotations

import functools
import itertools
import math
import time

import numpy as np

from ..._region_tree import RegionTree
from ..model._quality import quality_data
from . import _templates_luts as luts
from ._packed import pack_points

__all__ = ["cut_leaves", "lattice", "mark_corners", "template_mesh", "template_quality"]

#: Lattice size (points) above which vertices are numbered by searching the sorted keys
#: present instead of an intp prefix sum over the whole lattice, when the points are fewer
#: than 1/8 of it: the prefix sum costs 8 bytes per lattice point (8.6 GB at 1025^3 for
#: a mesh of a few hundred thousand points). Both give the same numbers.
DENSE_RANK_LIMIT = 1 << 25


def lattice(tree: RegionTree):
    """Shape and strides of the lattice of pixel corners of the padded grid.

    Keys are intp: numpy would convert any other index dtype on every gather.
    """
    shape = tuple(n + 1 for n in tree.padded_shape)
    strides = np.array([math.prod(shape[a + 1:]) for a in range(len(shape))], dtype=np.intp)
    return shape, strides


def mark_corners(tree: RegionTree, select: np.ndarray, shape, strides) -> np.ndarray:
    """Flat bool lattice: True at every corner of the selected leaves (one pass per level)."""
    d = tree.ndim
    is_vertex = np.zeros(math.prod(shape), dtype=bool)
    corner_keys = np.array(list(itertools.product((0, 1), repeat=d)), strides.dtype) @ strides
    for lev in np.unique(tree.level[select]):
        sel = select & (tree.level == lev)
        okey = tree.origin[sel].astype(strides.dtype) @ strides
        is_vertex[(okey[:, None] + (corner_keys << int(lev))[None]).ravel()] = True
    return is_vertex


def template_mesh(bal: RegionTree, meshed: np.ndarray, *, rule: str = "parity"):
    """Cut every meshed leaf by the look-up tables.

    `rule` is the 3-D face-diagonal rule (``_templates_luts``): ``"parity"`` (five
    tetrahedra per plain leaf) or ``"lowest"`` (Kuhn's six; what a periodic mesh with an
    odd extent needs, since a translation by an odd number of cells flips the parity).
    2-D meshes always use the lowest-corner rule.

    Returns points (index space), cells, leaf index and template id per element, the
    seconds spent per step, the points packed (``_packed.pack_points``; None when they
    do not fit) and the number of plain leaves (no edge midpoint or face centre a vertex).
    """
    d = bal.ndim
    seconds = {}
    t = time.perf_counter()
    shape, strides = lattice(bal)
    # vertices are the corners of every leaf inside the image, whatever its material:
    # then a face centre that is a vertex always comes with its four edge midpoints
    is_vertex = mark_corners(bal, bal.inside, shape, strides)
    leaves = np.flatnonzero(meshed)
    kd = strides.dtype
    level = bal.level[leaves].astype(kd)
    okey = bal.origin[leaves].astype(kd) @ strides  # (L,) lattice key of each leaf's lowest corner
    size = np.left_shift(kd.type(1), level)
    half = size >> 1
    site_keys = luts.SITES[d].astype(kd) @ strides  # (n_sites,)
    hanging = np.zeros((len(leaves), len(site_keys)), dtype=bool)
    coarse = np.flatnonzero(level >= 1)  # level-0 leaves have no sites: no leaf is smaller
    site_of_coarse = okey[coarse, None] + half[coarse, None] * site_keys[None]  # (Lc, n_sites)
    hanging[coarse] = is_vertex[site_of_coarse]
    plain = ~hanging.any(axis=1)
    variant = None
    if d == 3 and rule == "parity":
        # the leaf's parity: sum of its origin in units of its side
        parity = (bal.origin[leaves] >> bal.level[leaves, None]).sum(axis=1) & 1
        variant = (parity + 1).astype(np.int8)
    elif rule not in ("parity", "lowest"):
        raise ValueError(f"rule must be 'parity' or 'lowest'; got {rule!r}.")
    # the points elements use: corners of meshed leaves, the sites they carry, and the
    # new points of the templates (marked without scattering every element's keys)
    used = (is_vertex if meshed.sum() == bal.inside.sum()
            else mark_corners(bal, meshed, shape, strides))
    used[site_of_coarse[hanging[coarse]]] = True
    del site_of_coarse
    seconds["vertices"] = time.perf_counter() - t

    t = time.perf_counter()
    cells, which, template_of, _ = cut_leaves(okey, size, hanging, strides, used=used,
                                              variant=variant)
    leaf_of = leaves[which]  # intp: it indexes the leaf arrays again below
    del which
    seconds["simplices"] = time.perf_counter() - t

    t = time.perf_counter()
    points = np.stack(np.unravel_index(np.flatnonzero(used), shape), axis=1)
    packed = pack_points(points)          # the facet groups' pass reads corners from it
    points = points.astype(np.float64)
    seconds["numbering"] = time.perf_counter() - t
    return points, cells, leaf_of, template_of, seconds, packed, int(plain.sum())


def cut_leaves(okey: np.ndarray, size: np.ndarray, hanging: np.ndarray, strides: np.ndarray,
               *, used: np.ndarray | None = None, variant: np.ndarray | None = None):
    """Cut leaves by the look-up tables; the dictionary step, shared with the quality table.

    Parameters
    ----------
    okey : (L,) ndarray of int32 or int64
        Lattice key (``coords @ strides``) of each leaf's lowest corner.
    size : (L,) ndarray of the same dtype
        Leaf side in lattice units; leaves with a site present must have an even side.
    hanging : (L, n_sites) ndarray of bool
        Which of ``SITES[d]`` are vertices, per leaf.
    strides : (d,) ndarray of the same dtype
        Strides of the lattice; keys are linear, so a template's key is
        ``okey + scale * (local @ strides)``.
    used : (n_lattice,) ndarray of bool, optional
        Flat lattice marking the corners and sites present. When given, the templates' new
        points are marked in it, and elements come back as vertex numbers (the rank of the
        key among the marked points, i.e. ``cumsum(used) - 1``, or found by searching the
        sorted marked keys when the lattice is large and mostly empty) instead of keys, so
        the big key array is never built.
    variant : (L,) ndarray of int8, optional
        Diagonal rule per leaf (``VARIANTS[d]``, see ``_templates_luts``); default 0, the
        lowest-corner rule, for every leaf.

    Returns
    -------
    keys : (M, d+1) ndarray of intp
        Lattice key (or vertex number, with `used`) of every element vertex, positively
        oriented.
    which : (M,) ndarray of int32 (int64 for 2^31 leaves or more)
        Index (into the L leaves) of the leaf each element cuts.
    template_id : (M,) ndarray of int16
        Index into ``TEMPLATES[d]``.
    new_points : (K,) ndarray of the keys' dtype
        Keys of the points the templates add (leaf centres, face centres of fans), with
        repeats; every other element vertex is a leaf corner or a site present.
    """
    d = len(strides)
    kd = strides.dtype
    wd = np.int32 if len(okey) < 2**31 else np.int64
    half = size >> 1
    if variant is None:
        variant = np.zeros(len(okey), dtype=np.int8)
    plain = ~hanging.any(axis=1)
    other = np.flatnonzero(~plain)
    # sited leaves whose configuration the table cuts into fewer tetrahedra than cones
    tabled, entry, other = _table_entries(d, hanging, variant, other)
    # plain leaves by variant: (variant, members)
    plain_groups = [(v, np.flatnonzero(plain & (variant == v))) for v in luts.VARIANTS[d]]
    # the other leaves by the variant and case of each face: (variant, face, case, members)
    groups = []
    n_var = len(luts.VARIANTS[d])
    # one gather of the sited leaves' rows (a gather per site and face costs more)
    sites_of_other = hanging[other].view(np.uint8)
    variant_of_other = variant[other].astype(np.uint16)
    for f, fsites in enumerate(luts.FACE_SITES[d]):
        n_case = 1 << len(fsites)
        # uint16 codes (variant, case): numpy's stable sort is a radix sort for them
        code = variant_of_other << np.uint16(len(fsites))
        for bit, site in enumerate(fsites):
            code |= sites_of_other[:, site].astype(np.uint16) << np.uint16(bit)
        order = np.argsort(code, kind="stable")
        bounds = np.searchsorted(code[order], np.arange(n_var * n_case + 1), side="left")
        for v in luts.VARIANTS[d]:
            for case in range(n_case):
                lo, hi = bounds[v * n_case + case], bounds[v * n_case + case + 1]
                if hi > lo:
                    if len(luts.FACE_LUT[d][v][f][case]) == 0:
                        raise RuntimeError(f"leaf configuration outside the look-up table "
                                           f"(face {f}, case {case}); the tree is not "
                                           "balanced as assumed.")
                    groups.append((v, f, case, other[order[lo:hi]]))
    # tabled leaves exist only where _table_entries found the table
    per_entry = (np.diff(luts.LEAF_TABLE[d].offset)[entry] if len(tabled)
                 else np.zeros(0, np.int64))
    total = (sum(len(sel) * len(luts.PLAIN[d][v]) for v, sel in plain_groups)
             + sum(len(sel) * len(luts.FACE_LUT[d][v][f][c]) for v, f, c, sel in groups)
             + int(per_entry.sum()))
    new_parts = []
    for v, f, case, sel in groups:
        new_local = _new_points(d, v, f, case)
        if len(new_local):
            new_keys = new_local.astype(kd) @ strides
            new_parts.append((okey[sel, None] + half[sel, None] * new_keys[None]).ravel())
    if len(tabled):
        # the table's own new points (fan face centres, the centre where used), per leaf
        table = luts.LEAF_TABLE[d]
        starts = np.searchsorted(table.new_entry, np.arange(len(table.key) + 1))
        n_new = (starts[1:] - starts[:-1])[entry]
        leaf_of_new = np.repeat(tabled, n_new)
        row = np.repeat(starts[entry] - (np.cumsum(n_new) - n_new), n_new) + np.arange(n_new.sum())
        new_keys = table.new_point[row].astype(kd) @ strides
        new_parts.append(okey[leaf_of_new] + half[leaf_of_new] * new_keys)
    new_points = np.concatenate(new_parts) if new_parts else np.zeros(0, kd)
    vertex_id = present = None
    if used is not None:
        used[new_points] = True
        if used.size > DENSE_RANK_LIMIT and used.size > 8 * np.count_nonzero(used):
            present = np.flatnonzero(used)          # (n_points,) sorted keys
        else:
            vertex_id = np.cumsum(used, dtype=np.intp)
            vertex_id -= 1
    # write every block straight into its slice of the outputs (no concatenation copies)
    keys = np.empty((total, d + 1), dtype=kd)
    which = np.empty(total, dtype=wd)
    template_of = np.empty(total, dtype=np.int16)

    def emit(start, sel, scale, local_keys, template_ids):
        """Elements of the leaves `sel`: `local_keys` (t, d+1) shared by all, or
        (n, t, d+1) one row per leaf (then used as scratch), in units of `scale`;
        `template_ids` (t,) or (n, t)."""
        n, t = len(sel), local_keys.shape[-2]
        block = keys[start:start + n * t].reshape(n, t, d + 1)
        if vertex_id is None and present is None:
            np.multiply(scale[sel, None, None], local_keys, out=block)
            block += okey[sel, None, None]
        elif present is not None:              # the rank of each key among the present
            np.multiply(scale[sel, None, None], local_keys, out=block)
            block += okey[sel, None, None]
            block[...] = np.searchsorted(present, block)
        else:
            lattice_keys = np.multiply(scale[sel, None, None], local_keys,
                                       out=local_keys if local_keys.ndim == 3 else None)
            lattice_keys += okey[sel, None, None]
            np.take(vertex_id, lattice_keys, out=block)
        which[start:start + n * t].reshape(n, t)[:] = sel[:, None]
        template_of[start:start + n * t].reshape(n, t)[:] = template_ids
        return start + n * t

    start = 0
    # plain leaves: d! Kuhn simplices or five tetrahedra, in units of the leaf side
    for v, sel in plain_groups:
        if len(sel):
            simplices = luts.PLAIN[d][v]
            start = emit(start, sel, size, simplices.astype(kd) @ strides,
                         luts.PLAIN_TEMPLATE_ID[d][v] + np.arange(len(simplices)))
    # other leaves: every face by its own case, coned to the leaf centre (unit: half side)
    for v, f, case, sel in groups:
        lut = luts.FACE_LUT[d][v][f][case]
        start = emit(start, sel, half, lut.astype(kd) @ strides,
                     luts.FACE_TEMPLATE_ID[d][v][f][case] + np.arange(len(lut)))
    if len(tabled):
        # tabled leaves, grouped by their number of tetrahedra t (a few dozen groups):
        # each leaf takes its entry's row of t members (unit: half side)
        table = luts.LEAF_TABLE[d]
        rows = _member_rows(table)
        count = np.diff(table.offset)[entry]
        order = np.argsort(count, kind="stable")
        counts, first = np.unique(count[order], return_index=True)
        group_bounds = np.append(first, len(order)).tolist()
        local = table.simplex.astype(kd) @ strides              # (S, d+1)
        for t, lo, hi in zip(counts.tolist(), group_bounds[:-1], group_bounds[1:]):
            # np.take, not fancy indexing: whole rows copied, no per-element iterator
            members = np.take(rows[:, :t], entry[order[lo:hi]], axis=0)      # (n, t)
            start = emit(start, tabled[order[lo:hi]], half,
                         np.take(local, members, axis=0), members + luts.TABLE_FIRST_ID[d])
    return keys, which, template_of, new_points


@functools.lru_cache(maxsize=2)
def _member_rows(table: luts.LeafTable) -> np.ndarray:
    # intp: numpy would convert any other index dtype on every gather
    return table.member_rows.astype(np.intp)


def _table_entries(d: int, hanging: np.ndarray, variant: np.ndarray, sited: np.ndarray):
    """Split the sited leaves into those the leaf table cuts and the rest:
    (tabled leaves, their table entries, the other leaves)."""
    table = luts.LEAF_TABLE.get(d)
    empty = np.zeros(0, dtype=sited.dtype)
    if table is None or not len(table.key) or not len(sited):
        return empty, np.zeros(0, np.int64), sited
    # the 18 site bits of each leaf, packed little-endian into 3 bytes, then one int32
    packed = np.packbits(hanging[sited], axis=1, bitorder="little").astype(np.int32)
    code = variant[sited].astype(np.int32) << np.int32(hanging.shape[1])
    for byte in range(packed.shape[1]):
        code |= packed[:, byte] << np.int32(8 * byte)
    pos = np.minimum(np.searchsorted(table.key, code), len(table.key) - 1)
    hit = table.key[pos] == code
    return sited[hit], pos[hit].astype(np.int64), sited[~hit]


@functools.cache
def _new_points(d: int, variant: int, face: int, case: int) -> np.ndarray:
    """(k, d) local points of a face case that are neither corners nor sites present."""
    present = {tuple(luts.SITES[d][s])
               for i, s in enumerate(luts.FACE_SITES[d][face]) if case >> i & 1}
    pts = {tuple(p) for p in luts.FACE_LUT[d][variant][face][case].reshape(-1, d).tolist()}
    new = [p for p in sorted(pts) if p not in present and any(c == 1 for c in p)]
    return np.array(new, dtype=np.int64).reshape(-1, d)


def template_quality(d: int, spacing: tuple[float, ...]) -> dict[str, np.ndarray]:
    """Quality of every template simplex once scaled by `spacing`: (n_templates,) arrays."""
    tpl = luts.TEMPLATES[d] * np.asarray(spacing)  # (n, d+1, d)
    pts = tpl.reshape(-1, d)
    cells = np.arange(len(pts)).reshape(-1, d + 1)
    return quality_data(pts, cells)
