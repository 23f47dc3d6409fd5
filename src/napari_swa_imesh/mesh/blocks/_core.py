"""Block-wise template meshing: one piece per block, conforming across blocks.

The template mesher is local: a leaf's elements depend only on the leaf and on which of
its edge midpoints and face centres are vertices (corners of the leaves touching it),
every vertex is a lattice point and every face diagonal follows a parity rule of the
leaf's absolute position. So a block can be meshed alone if it knows the balanced tree
around it. Steps:

1. per block (a task): the "mixed" grids of the region tree, ``mixed[k]`` (shape
   ``block >> k``) says whether each level-k cell holds more than one label. Blocks are
   cubes of ``B = 2**top`` voxels (the tree's roots), so a cell never spans two blocks;
2. once, on the coarse grids only (``N / 7`` booleans in all): the global 2:1 balance
   ``split[k] = mixed[k] | any_children(dilate(split[k-1]))`` (``_balance``'s recurrence);
3. per block (a task): the balanced leaves touching the block from the split grids, their
   labels from the block's voxels and a one-voxel halo, and the template mesh of the
   leaves the block owns, in a local frame shifted by a multiple of ``B`` whose parity
   sum is even (the diagonal rule is unchanged). Global vertex ids are lattice keys of
   the image's corner lattice: no communication. Its facet groups, seams, volumes and
   own checks come from the template tables (``_piece``), not from a sort of facets.

The pieces are exactly the in-memory mesh of the same tree cut by blocks: same points,
same elements, same facet groups (``tests/mesh/test_blocks.py``). The tree's roots are
the blocks, so when ``B`` is smaller than ``mesh_labels``'s default root (``2**floor(log2
(min(shape)))``) a leaf larger than a block is cut into blocks: the mesh is then that of
``build_tree(labels, top_level=log2(B))``.

Grid conventions: ``split[k]`` covers the padded grid (``padded_shape >> k``); a block's
slice of it is one level-k cell wider on every side (clipped at the grid), with its
offset.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from ..._region_tree import PAD_LABEL, RegionTree, _fold_pairs
from ..formats._common import material_names
from ..mesher._balance import _any_children, _dilate
from ..mesher._packed import pack_points
from ..mesher._templates import template_mesh, template_quality
from . import _periodic
from . import _piece as pc

__all__ = [
    "BlockPlan",
    "Piece",
    "assemble",
    "balance_grids",
    "block_slices",
    "group_table",
    "mesh_block",
    "mixed_grids",
    "plan_blocks",
    "seam_mismatches",
]


@dataclass(frozen=True)
class BlockPlan:
    """How a volume is cut: blocks of ``block`` voxels per axis, the tree's roots.

    Attributes
    ----------
    shape : tuple of int
        The shape of the lattice meshed: the label volume's, times `factors`.
    block : int
        Block side in lattice cells, ``2**top``.
    factors : tuple of int
        Lattice cells per voxel along each axis (anisotropic voxels subdivided as the
        in-memory mesher does; empty: one).
    max_level : int, optional
        Largest leaf level (a size cap: every cell above it is split, as
        ``_lattice.lattice_tree``'s ``max_size`` does).
    periodic : bool
        Leaves touching the image box are split to one lattice cell (``_periodic``).
    coarsen : int
        Voxels are voted in cubes of ``2**coarsen`` first (``_coarsen``).
    """

    shape: tuple[int, ...]
    block: int
    factors: tuple[int, ...] = ()
    max_level: int | None = None
    periodic: bool = False
    coarsen: int = 0

    @property
    def rule(self) -> str:
        """The 3-D face-diagonal rule of the mesh (the in-memory mesher's)."""
        return _periodic.diagonal_rule(self.shape, self.periodic)

    @property
    def top(self) -> int:
        return int(self.block).bit_length() - 1

    @property
    def grid(self) -> tuple[int, ...]:
        """Blocks per axis."""
        return tuple(-(-n // self.block) for n in self.shape)

    @property
    def padded_shape(self) -> tuple[int, ...]:
        return tuple(g * self.block for g in self.grid)

    @property
    def n_blocks(self) -> int:
        return int(np.prod(self.grid))

    def blocks(self) -> list[tuple[int, ...]]:
        """Block indices in C order."""
        return list(itertools.product(*(range(g) for g in self.grid)))

    def box(self, index) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) voxel corners of block `index` in the padded grid."""
        lo = np.asarray(index, np.int64) * self.block
        return lo, lo + self.block

    def window(self, index) -> tuple[tuple[slice, ...], tuple[tuple[int, int], ...]]:
        """Slices of the image to read for block `index` (its box and a one-voxel halo,
        clipped to the image) and the padding that completes them to ``block + 2``."""
        lo, hi = self.box(index)
        slices, pads = [], []
        for a, n in enumerate(self.shape):
            start, stop = max(0, lo[a] - 1), min(n, hi[a] + 1)
            stop = max(stop, start)
            slices.append(slice(int(start), int(stop)))
            pads.append((int(start - (lo[a] - 1)), int(hi[a] + 1 - max(stop, start))))
        return tuple(slices), tuple(pads)

    def voxel_window(self, index) -> tuple[tuple[slice, ...], tuple[slice, ...]]:
        """The voxels to read for block `index` (its :meth:`window` in voxels) and the
        slices of those voxels, repeated by :attr:`factors`, that give the window."""
        vox, crop = [], []
        for s, f in zip(self.window(index)[0], self.factors or (1,) * len(self.shape)):
            a = s.start // f
            vox.append(slice(a, -(-s.stop // f)))
            crop.append(slice(s.start - a * f, s.stop - a * f))
        return tuple(vox), tuple(crop)

    def to_lattice(self, voxels: np.ndarray, index) -> np.ndarray:
        """The window of block `index` from its :meth:`voxel_window` voxels."""
        for axis, f in enumerate(self.factors):
            if f > 1:
                voxels = np.repeat(voxels, f, axis=axis)
        return voxels[self.voxel_window(index)[1]] if self.factors else voxels


def default_top(shape) -> int:
    """``mesh_labels``'s root level for `shape` (``_tree.default_top_level``)."""
    return max(0, int(np.floor(np.log2(max(1, min(shape))))))


def plan_blocks(shape, block: int | None = None, *, factors=(), max_level: int | None = None,
                periodic: bool = False, coarsen: int = 0) -> BlockPlan:
    """The block plan of a volume: `block` a power of two, at most the default root.

    `shape` is the volume's; with `factors` (cells per voxel) the plan is on its lattice,
    of ``shape * factors`` cells. Raises ValueError for a block that is not a power of
    two of at least 2 cells.
    """
    factors = tuple(int(f) for f in factors) if any(int(f) != 1 for f in factors) else ()
    shape = tuple(int(n) * (factors[a] if factors else 1) for a, n in enumerate(shape))
    cap = 1 << default_top(shape)
    if block is None:
        block = cap
    block = int(block)
    if block < 2 or block & (block - 1):
        raise ValueError(f"block must be a power of two of at least 2 voxels; got {block}.")
    return BlockPlan(shape, min(block, max(2, cap)), factors, max_level, bool(periodic),
                     int(coarsen))


def _window_labels(plan: BlockPlan, index, data: np.ndarray) -> np.ndarray:
    """The block's window (box plus one voxel each side) as int64, PAD_LABEL outside."""
    _, pads = plan.window(index)
    return np.pad(np.asarray(data).astype(np.int64, copy=False), pads, mode="constant",
                  constant_values=PAD_LABEL)


def mixed_grids(window: np.ndarray, top: int) -> list[np.ndarray]:
    """``mixed[k]`` for k = 1..top of one block (its window from :func:`_window_labels`):
    (block >> k,)*d bool, the level-k cell holds two labels (padding counts as one)."""
    d = window.ndim
    cur = window[(slice(1, -1),) * d]
    mixed_marker = np.iinfo(np.int64).min
    out = []
    for _ in range(top):
        coarse = tuple(n // 2 for n in cur.shape)
        blocks = cur.reshape(sum(((c, 2) for c in coarse), ()))
        lo = _fold_pairs(np.minimum, blocks, d)
        hi = _fold_pairs(np.maximum, blocks, d)
        homog = (lo == hi) & (lo != mixed_marker)
        out.append(~homog)
        cur = np.where(homog, lo, mixed_marker)
    return out


def balance_grids(plan: BlockPlan, mixed_of: dict) -> list[np.ndarray | None]:
    """The global split grids (index k = level; ``[0]`` is None) from every block's
    :func:`mixed_grids` (``mixed_of[index]``), balanced across faces and edges."""
    d = len(plan.shape)
    split: list[np.ndarray | None] = [None]
    for k in range(1, plan.top + 1):
        grid = np.zeros(tuple(n >> k for n in plan.padded_shape), dtype=bool)
        side = plan.block >> k
        for index, mixed in mixed_of.items():
            grid[tuple(slice(i * side, (i + 1) * side) for i in index)] = mixed[k - 1]
        if plan.periodic:
            grid |= _periodic.box_cells(plan.shape, grid.shape, k)
        below = split[k - 1]
        if plan.max_level is not None and k > plan.max_level:
            grid[...] = True                                     # the size cap
        elif below is not None and below.any():
            grid |= _any_children(_dilate(below, max(1, d - 1)))
        split.append(grid)
    return split


def block_slices(plan: BlockPlan, split: list, index) -> list:
    """Each level's split grid around block `index`: ``[(offset, grid), ...]`` for levels
    1..top (``[0]`` None), one cell wider than the block on every side, clipped."""
    lo, hi = plan.box(index)
    out: list = [None]
    for k in range(1, plan.top + 1):
        g = split[k]
        start = np.maximum((lo >> k) - 1, 0)
        stop = np.minimum((hi >> k) + 1, g.shape)
        out.append((start, g[tuple(slice(int(a), int(b)) for a, b in zip(start, stop))].copy()))
    return out


def _leaves_near(plan: BlockPlan, index, grids: list):
    """(origin (L, d) int64, level (L,) int8) of the balanced leaves whose closed box
    meets the block's closed box, from the block's split slices."""
    lo, hi = plan.box(index)
    d = len(plan.shape)
    top = plan.top
    origins, levels = [], []
    for k in range(top + 1):
        if k == 0:
            if top < 1 or grids[1][1] is None:
                continue
            off1, g1 = grids[1]
            # voxels in split level-1 cells: the 2^d children of each split cell
            cells = np.argwhere(g1) + off1
            kids = np.array(list(itertools.product((0, 1), repeat=d)), np.int64)
            org = ((cells << 1)[:, None, :] + kids[None]).reshape(-1, d)
        else:
            off, g = grids[k]
            leaf = ~g
            if k < top:
                offp, gp = grids[k + 1]
                cells = np.argwhere(leaf) + off
                parent = (cells >> 1) - offp
                ok = np.all((parent >= 0) & (parent < gp.shape), axis=1)
                keep = np.zeros(len(cells), bool)
                keep[ok] = gp[tuple(parent[ok].T)]
                cells = cells[keep]
            else:
                cells = np.argwhere(leaf) + off
            org = cells << k
        s = 1 << k
        touch = np.all((org <= hi) & (org + s >= lo), axis=1)
        origins.append(org[touch])
        levels.append(np.full(int(touch.sum()), k, np.int8))
    return np.concatenate(origins), np.concatenate(levels)


@dataclass
class Piece:
    """One block's mesh: global lattice points and ids, elements, data, groups, seams.

    Attributes
    ----------
    index : tuple of int
    points : (N, d) ndarray of int64
        Lattice (voxel-corner) coordinates.
    gid : (N,) ndarray of int64
        Global vertex id: the point's key in the image's corner lattice (C order).
    cells : (M, d+1) ndarray of intp
        Positively oriented in index space.
    material, quality, level : (M,) ndarray
    groups : dict of str to (facets (F, d) intp, owner (F,) intp)
        The piece's own facet groups: box sides, interfaces it owns (material A side),
        exteriors.
    seams : dict of (axis, side) to (S, d) ndarray of int64
        Sorted global ids of the boundary facets facing the neighbour block, rows sorted.
    problems : list of str
        What the piece's own checks found (empty: conforming inside, positive volumes).
    volumes : dict of int to int
        Volume per material in voxels, times ``d!`` (exact integers).
    """

    index: tuple
    points: np.ndarray
    gid: np.ndarray
    cells: np.ndarray
    material: np.ndarray
    quality: np.ndarray
    level: np.ndarray
    groups: dict = field(default_factory=dict)
    seams: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    volumes: dict = field(default_factory=dict)


def group_table(d: int, present, names: dict | None = None) -> dict[str, int]:
    """Group name -> id (1..K) for a mesh whose meshed materials are `present`: box sides,
    interfaces ``A < B``, exteriors; the same in every piece."""
    present = np.asarray(sorted(int(m) for m in present), np.int64)
    nm = material_names(names or {}, present)
    table = [f"{ax}{end}" for ax in "xyz"[:d] for end in ("min", "max")]
    table += [f"interface_{nm[int(a)]}_{nm[int(b)]}" for i, a in enumerate(present)
              for b in present[i + 1:]]
    table += [f"exterior_{nm[int(a)]}" for a in present]
    return {name: i + 1 for i, name in enumerate(table)}


def _frame(origin: np.ndarray, level: np.ndarray, meshed: np.ndarray):
    """(shift (d,), extent) of the local frame around the leaves: the lowest corner
    rounded down to a multiple of ``2**(K+1)`` (K the largest meshed level), so
    ``(origin - shift) >> k`` keeps its parity for every meshed leaf and the diagonal
    rule is unchanged; the frame reaches the far side of the farthest leaf."""
    step = np.int64(2) << int(level[meshed].max())
    shift = (origin.min(axis=0) // step) * step
    far = (origin + (np.int64(1) << level.astype(np.int64))[:, None]).max(axis=0)
    return shift, tuple(int(n) for n in far - shift)


def mesh_block(plan: BlockPlan, index, data: np.ndarray, grids: list, *,
               exclude=(), present=(), material_names_: dict | None = None,
               spacing=None) -> Piece:
    """Mesh the leaves block `index` owns.

    Parameters
    ----------
    plan : BlockPlan
    index : tuple of int
    data : ndarray of int
        The image read over ``plan.window(index)[0]``.
    grids : list
        :func:`block_slices` of the global split grids.
    exclude : sequence of int
        Materials not meshed.
    present : sequence of int
        Every meshed material of the whole volume (names the groups alike everywhere).
    material_names_ : dict, optional
    spacing : sequence of float, optional
        Voxel spacing (the elements' quality is measured in physical units).

    Returns
    -------
    Piece
    """
    d = len(plan.shape)
    lo, hi = plan.box(index)
    win = _window_labels(plan, index, data)
    origin, level = _leaves_near(plan, index, grids)
    # a voxel of each leaf inside the window (leaves meet the closed box)
    probe = np.clip(origin, lo - 1, hi) - (lo - 1)
    label = win[tuple(probe.T)]
    owned = np.all((origin >= lo) & (origin < hi), axis=1)
    exclude = np.asarray(list(exclude), np.int64)
    meshed = owned & (label != PAD_LABEL) & ~np.isin(label, exclude)
    empty = Piece(tuple(index), np.zeros((0, d), np.int64), np.zeros(0, np.int64),
                  np.zeros((0, d + 1), np.intp), np.zeros(0, np.int64), np.zeros(0),
                  np.zeros(0, np.int8))
    if not meshed.any():
        return empty
    shift, extent = _frame(origin, level, meshed)
    local = RegionTree(origin - shift, level, label, extent, extent, plan.top)
    pts, cells, leaf_of, template_id, _, packed, _ = template_mesh(local, meshed,
                                                                   rule=plan.rule)
    points = pts.astype(np.int64) + shift
    del pts
    table = template_quality(d, tuple(spacing) if spacing is not None else (1.0,) * d)
    strides = np.array([int(np.prod([n + 1 for n in plan.shape[a + 1:]])) for a in range(d)],
                       np.int64)
    piece = Piece(tuple(index), points, points @ strides, cells.astype(np.intp, copy=False),
                  label[leaf_of], table["quality"][template_id], level[leaf_of])
    _piece_facets(piece, plan, win, exclude, present, material_names_ or {},
                  template_id, leaf_of, origin, level, label, meshed, packed)
    return piece


def _piece_facets(piece: Piece, plan: BlockPlan, win: np.ndarray, exclude: np.ndarray,
                  present, names: dict, template_id, leaf_of, origin, level, label,
                  meshed, packed) -> None:
    """The piece's facet groups, seams, exact volumes and its own checks: positive
    volumes, and the chain of its facets less the box sides, exteriors and seams
    vanishing (no hanging vertex, hole or doubled facet inside the block)."""
    d = len(plan.shape)
    lo, hi = plan.box(piece.index)
    cells, material, gid = piece.cells, piece.material, piece.gid
    nm = material_names(names, np.asarray(sorted(int(m) for m in present), np.int64))
    values = pc.vertex_values(gid)
    if packed is None:                    # a frame too wide for 63 bits: pack the points
        packed = pack_points(piece.points - piece.points.min(axis=0))
    per_leaf, bad, chain = pc.piece_pass(packed, cells, values, leaf_of, len(origin),
                                         plan.block)
    if bad:
        piece.problems.append(f"{bad} elements without positive volume")
    mats, inv = np.unique(label[meshed], return_inverse=True)
    sums = np.zeros(len(mats), np.int64)
    np.add.at(sums, inv.ravel(), per_leaf[meshed])
    piece.volumes = {int(m): int(v) for m, v in zip(mats, sums)}
    ob, qb, axis, out, value, inside_image, in_block = pc.probe_facets(
        win, lo, hi, plan.shape, cells, template_id, leaf_of, origin, level, label, meshed)
    mine = material[ob]
    groups: dict[str, list] = {}
    fb = pc.outward_facets(cells, ob, qb)                            # (F, d) outward of ob

    def add(name, sel):
        if sel.any():
            groups.setdefault(name, []).append((fb[sel], ob[sel]))

    for a in range(d):                                             # box sides
        name = "xyz"[d - 1 - a]
        for end, sign in (("min", -1), ("max", 1)):
            add(f"{name}{end}", ~inside_image & (axis == a) & (out == sign))
    ex = inside_image & np.isin(value, exclude)
    for m in np.unique(mine[ex]).tolist():
        add(f"exterior_{nm[m]}", ex & (mine == m))
    meshed_across = inside_image & ~np.isin(value, exclude) & (value != PAD_LABEL)
    owns = meshed_across & (value > mine)        # interfaces, from the lower material
    for a, b in set(zip(mine[owns].tolist(), value[owns].tolist())):
        add(f"interface_{nm[a]}_{nm[b]}", owns & (mine == a) & (value == b))
    seam = meshed_across & ~in_block
    for a in range(d):
        for sign in (-1, 1):
            ids = np.sort(gid[fb[seam & (axis == a) & (out == sign)]], axis=1)
            piece.seams[(a, sign)] = ids[np.lexsort(ids.T[::-1])] if len(ids) else ids
    single = fb[~meshed_across | ~in_block]                      # box, exteriors, seams
    if (chain - pc.facet_chain(single, values)) & ((1 << 64) - 1):
        piece.problems.append("its facets do not pair up inside the block (a hanging vertex, "
                              "a hole or a facet seen twice from one side)")
    piece.groups = {name: (np.concatenate([f for f, _ in parts]),
                           np.concatenate([o for _, o in parts]))
                    for name, parts in groups.items()}


def seam_mismatches(plan: BlockPlan, seams: dict) -> list[str]:
    """Compare the facets each pair of face-neighbour blocks puts on their shared face.

    `seams` maps a block index to its :attr:`Piece.seams` (missing: an empty piece).
    Returns one sentence per face where the two sides differ (empty: no seam).
    """
    d = len(plan.shape)
    out = []
    empty = np.zeros((0, d), np.int64)
    for index in plan.blocks():
        for a in range(d):
            nb = list(index)
            nb[a] += 1
            if nb[a] >= plan.grid[a]:
                continue
            mine = seams.get(tuple(index), {}).get((a, 1), empty)
            theirs = seams.get(tuple(nb), {}).get((a, -1), empty)
            if mine.shape != theirs.shape or not np.array_equal(mine, theirs):
                out.append(f"blocks {tuple(index)} and {tuple(nb)} disagree on their shared "
                           f"face ({len(mine)} vs {len(theirs)} facets)")
    return out


def assemble(pieces: list[Piece], plan: BlockPlan, spacing=None):
    """The pieces as one mesh: (points (N, d) float64 physical, cells, material, quality,
    groups {name: (facets, owner)}); points in global-id order."""
    d = len(plan.shape)
    spacing = np.ones(d) if spacing is None else np.asarray(spacing, float)
    pieces = [p for p in pieces if len(p.cells)]
    gids = np.concatenate([p.gid for p in pieces]) if pieces else np.zeros(0, np.int64)
    uniq, inverse = np.unique(gids, return_inverse=True)
    pts = np.zeros((len(uniq), d), np.int64)
    starts = np.cumsum([0] + [len(p.gid) for p in pieces])
    cells, mats, qual, offsets = [], [], [], [0]
    groups: dict[str, list] = {}
    for p, s in zip(pieces, starts[:-1]):
        local = inverse[s:s + len(p.gid)]
        pts[local] = p.points
        cells.append(local[p.cells])
        mats.append(p.material)
        qual.append(p.quality)
        for name, (f, o) in p.groups.items():
            groups.setdefault(name, []).append((local[f], o + offsets[-1]))
        offsets.append(offsets[-1] + len(p.cells))
    merged = {n: (np.concatenate([f for f, _ in v]), np.concatenate([o for _, o in v]))
              for n, v in groups.items()}
    def cat(xs, w):
        return np.concatenate(xs) if xs else np.zeros((0,) * w)
    return (pts * spacing,
            cat(cells, 2).astype(np.intp) if cells else np.zeros((0, d + 1), np.intp),
            cat(mats, 1).astype(np.int64) if mats else np.zeros(0, np.int64),
            cat(qual, 1) if qual else np.zeros(0), merged)
