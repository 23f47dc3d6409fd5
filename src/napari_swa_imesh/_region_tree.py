"""Region 2^d-tree of a label image, built bottom-up level by level (n-D, vectorised).

Conventions
-----------
* A leaf is an axis-aligned block of side ``2**level`` pixels whose pixels all carry one
  label, and whose parent block does not (a *maximal homogeneous block*).
* The tree covers a padded grid: every axis is padded at its far end to a multiple of
  ``2**top_level``. Padding pixels carry ``PAD_LABEL`` (-1), so no leaf ever mixes image
  and padding; padding leaves are kept (callers drop them with ``tree.inside``) because
  the mesher needs to know where the image ends.
* The top of the tree is a *forest* of roots of side ``2**top_level``; by default
  ``top_level = floor(log2(min(shape)))`` so a long thin image is not padded to a huge cube.

The segmentation side uses the tree for samples from a ground truth, the mesher for its
leaves; both call :func:`build_tree`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validation import as_labels

__all__ = ["PAD_LABEL", "RegionTree", "build_tree", "leaf_finder", "pad_to_multiple"]

PAD_LABEL = -1


@dataclass(frozen=True)
class RegionTree:
    """Leaves of a region 2^d-tree.

    Attributes
    ----------
    origin : (L, d) ndarray of int64
        Lowest corner of each leaf, in pixel indices of the (padded) grid.
    level : (L,) ndarray of int8
        Each leaf has side ``2**level`` pixels.
    label : (L,) ndarray of int64
        The label of every pixel in the leaf; ``PAD_LABEL`` for padding.
    shape : tuple of int
        Shape of the image the tree was built from.
    padded_shape : tuple of int
        Shape of the padded grid covered by the leaves.
    top_level : int
        Level of the roots.
    """

    origin: np.ndarray
    level: np.ndarray
    label: np.ndarray
    shape: tuple[int, ...]
    padded_shape: tuple[int, ...]
    top_level: int

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def inside(self) -> np.ndarray:
        """(L,) bool: the leaf lies in the image (not padding)."""
        return self.label != PAD_LABEL

    @property
    def size(self) -> np.ndarray:
        """(L,) int64: side length of each leaf in pixels."""
        return np.left_shift(1, self.level.astype(np.int64))

    def __len__(self) -> int:
        return int(self.level.size)

    def select(self, mask: np.ndarray) -> RegionTree:
        """Return a tree holding only the leaves where `mask` is true."""
        return RegionTree(self.origin[mask], self.level[mask], self.label[mask],
                          self.shape, self.padded_shape, self.top_level)

    def to_image(self, *, fill: int = PAD_LABEL, values: np.ndarray | None = None,
                 crop: bool = True, dtype=None) -> np.ndarray:
        """Paint every leaf's label (or ``values``) back into an array.

        Used by tests to prove the leaves tile the image exactly. Costs one loop per
        level, not per leaf. `dtype` (default: int64 for integer values) must hold the
        values and `fill`.
        """
        vals = self.label if values is None else np.asarray(values)
        if dtype is None:
            dtype = (np.result_type(vals.dtype, np.int64) if vals.dtype.kind in "iub"
                     else vals.dtype)
        out = np.full(self.padded_shape, fill, dtype=dtype)
        d = self.ndim
        for lev in np.unique(self.level):
            sel = self.level == lev
            s = 1 << int(lev)
            coarse_shape = tuple(n // s for n in self.padded_shape)
            # (n0, s, n1, s, ...) view of the output: paint whole blocks at once
            view = out.reshape(sum(((c, s) for c in coarse_shape), ()))
            idx = tuple(self.origin[sel, a] // s for a in range(d))
            block = vals[sel].reshape((-1,) + (1,) * d)
            full_idx = []
            for a in range(d):
                full_idx += [idx[a], slice(None)]
            # advanced indices are separated by slices, so numpy moves them first
            view[tuple(full_idx)] = block
        if crop:
            out = out[tuple(slice(0, n) for n in self.shape)]
        return out


# Morton (Z-order) bit spreading: every aligned 2^k block is one interval of codes, so a
# pixel's leaf is the last leaf whose code is <= the pixel's. (shift, mask) per step.
_SPREAD = {
    2: (0xFFFFFFFF, ((16, 0x0000FFFF0000FFFF), (8, 0x00FF00FF00FF00FF), (4, 0x0F0F0F0F0F0F0F0F),
                     (2, 0x3333333333333333), (1, 0x5555555555555555))),
    3: (0x1FFFFF, ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                   (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249))),
}
_MORTON_BITS = {2: 31, 3: 21}


def _morton(coords: np.ndarray) -> np.ndarray:
    """(K, d) non-negative ints -> (K,) uint64 Z-order codes (d = 2, 3)."""
    d = coords.shape[1]
    first, steps = _SPREAD[d]
    code = np.zeros(len(coords), np.uint64)
    x, tmp = np.empty_like(code), np.empty_like(code)  # in place: three buffers in all
    for a in range(d):
        x[:] = coords[:, a]
        x &= np.uint64(first)
        for shift, mask in steps:
            np.left_shift(x, np.uint64(shift), out=tmp)
            x |= tmp
            x &= np.uint64(mask)
        np.left_shift(x, np.uint64(d - 1 - a), out=tmp)
        code |= tmp
    return code


def leaf_finder(tree: RegionTree):
    """A function from pixels to the leaves that hold them.

    Parameters
    ----------
    tree : RegionTree

    Returns
    -------
    callable
        ``find(pixels)`` with pixels ``(K, d)`` int in the padded grid returns ``(K,)``
        intp leaf indices. In 2-D and 3-D it searches the leaves' Morton codes (O(K log L),
        nothing of image size); otherwise it reads a painted leaf-index image.

    Examples
    --------
    >>> t = build_tree(np.array([[1, 1], [1, 2]]))
    >>> int(t.label[leaf_finder(t)(np.array([[1, 1]]))[0]])
    2
    """
    d = tree.ndim
    if d in _MORTON_BITS and max(tree.padded_shape) <= 1 << _MORTON_BITS[d]:
        codes = _morton(tree.origin)
        order = np.argsort(codes, kind="stable")
        sorted_codes = codes[order]

        def find(pixels):
            return order[np.searchsorted(sorted_codes, _morton(pixels), side="right") - 1]
        return find
    leaf_map = tree.to_image(values=np.arange(len(tree)), crop=False)
    return lambda pixels: leaf_map[tuple(np.asarray(pixels).T)]


def pad_to_multiple(array: np.ndarray, block: int, value) -> np.ndarray:
    """Pad every axis at its far end to a multiple of `block` with `value`."""
    pad = [(0, (-n) % block) for n in array.shape]
    if not any(p for _, p in pad):
        return array
    return np.pad(array, pad, mode="constant", constant_values=value)


def default_top_level(shape: tuple[int, ...]) -> int:
    """Root level used when none is given: the largest dyadic block the smallest axis holds."""
    return max(0, int(np.floor(np.log2(max(1, min(shape))))))


def build_tree(labels, *, top_level: int | None = None) -> RegionTree:
    """Build the region 2^d-tree of a label image.

    Parameters
    ----------
    labels : (M, N[, P, ...]) array_like of int
        Label image, any number of axes, any size per axis (non-dyadic sizes are padded).
    top_level : int, optional
        Level of the roots; default ``floor(log2(min(labels.shape)))``.

    Returns
    -------
    RegionTree
        Its leaves are the maximal homogeneous blocks of the padded image.

    Notes
    -----
    Each level halves every axis, so the whole build is O(N) in the pixel count and keeps
    two label arrays alive (the current level and its parent).

    Examples
    --------
    >>> t = build_tree(np.array([[1, 1], [1, 2]]))
    >>> len(t), sorted(t.label.tolist())
    (4, [1, 1, 1, 2])
    >>> len(build_tree(np.ones((4, 4), int)))
    1
    """
    lab = as_labels(labels, min_ndim=1)
    if top_level is not None and int(top_level) < 0:
        raise ValueError(f"top_level must be >= 0; got {top_level}.")
    return _build_tree(lab, top_level=top_level)


def _signed_labels(lab: np.ndarray) -> np.ndarray:
    """Labels (from ``as_labels``) in a signed dtype with room for the two markers.

    ``PAD_LABEL`` (-1) and the dtype's minimum (a mixed block) are never labels, so any
    signed dtype works as it is; unsigned labels are re-read as the signed type of the
    same width when they fit (a view, no copy), else widened once.
    """
    if lab.dtype.kind == "i":
        return lab
    signed = np.dtype(f"i{lab.dtype.itemsize}")
    if lab.size and lab.max() > np.iinfo(signed).max:
        return lab.astype(np.dtype(f"i{min(8, 2 * lab.dtype.itemsize)}"))
    return lab.view(signed)


def _fold_pairs(op, blocks: np.ndarray, d: int) -> np.ndarray:
    """(c0, 2, c1, 2, ...) -> (c0, c1, ...): `op` of the two children, one axis at a time.

    A fold over axes on views: no copy of the level (a transpose-and-reshape to put the
    2^d children last would copy it), and each step halves the data.
    """
    out = blocks
    for a in range(d):
        lead = (slice(None),) * (a + 1)  # axes a already folded sit before the pair axis
        out = op(out[lead + (0,)], out[lead + (1,)])
    return out


def _build_tree(lab: np.ndarray, *, top_level: int | None = None) -> RegionTree:
    """The worker behind :func:`build_tree`; `lab` comes from ``as_labels`` (trusted)."""
    shape = tuple(lab.shape)
    lab = _signed_labels(lab)
    d = lab.ndim
    top = default_top_level(lab.shape) if top_level is None else int(top_level)
    padded = pad_to_multiple(lab, 1 << top, PAD_LABEL)
    mixed = np.iinfo(padded.dtype).min  # marks a block that is not homogeneous

    origins, levels, labs = [], [], []
    cur = padded
    for k in range(1, top + 1):
        coarse = tuple(n // 2 for n in cur.shape)
        pairs = sum(((c, 2) for c in coarse), ())  # (c0, 2, c1, 2, ...): children per axis
        blocks = cur.reshape(pairs)
        lo = _fold_pairs(np.minimum, blocks, d)
        hi = _fold_pairs(np.maximum, blocks, d)
        homog = (lo == hi) & (lo != mixed)
        # homogeneous children of a mixed parent are leaves at level k-1
        child_leaf = cur != mixed
        np.logical_and(child_leaf.reshape(pairs), ~homog.reshape(sum(((c, 1) for c in coarse), ())),
                       out=child_leaf.reshape(pairs))
        idx = np.nonzero(child_leaf)
        del child_leaf
        if idx[0].size:
            origins.append(np.stack(idx, axis=1).astype(np.int64) << (k - 1))
            levels.append(np.full(idx[0].size, k - 1, np.int8))
            labs.append(cur[idx].astype(np.int64))
        cur = np.where(homog, lo, mixed)
    idx = np.nonzero(cur != mixed)
    if idx[0].size:
        origins.append(np.stack(idx, axis=1).astype(np.int64) << top)
        levels.append(np.full(idx[0].size, top, np.int8))
        labs.append(cur[idx].astype(np.int64))
    return RegionTree(
        origin=np.concatenate(origins) if origins else np.zeros((0, d), np.int64),
        level=np.concatenate(levels) if levels else np.zeros(0, np.int8),
        label=np.concatenate(labs) if labs else np.zeros(0, np.int64),
        shape=shape,
        padded_shape=tuple(padded.shape),
        top_level=top,
    )
