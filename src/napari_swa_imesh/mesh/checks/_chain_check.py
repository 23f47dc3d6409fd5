"""The default checks of a mesh whose points lie on the pixel lattice, without a sort.

The general checks (``_checks``) pair all ``(d+1) * M`` facet occurrences by sorting
integer keys: several seconds at volume size. A mesh whose points are integers in
pixel units, or in units of 2**-K pixel (every template mesh; ``--refine K``), is checked
here instead, in one pass over the elements:

* volumes, leaves and labels as ``_checks._elements`` does, in integers;
* conformity as a boundary: the facets of all elements, each taken with the
  orientation its element gives it (the chain ``∂(sum of elements)``), less the facets
  that may stay single (on a pixel plane with the pixel across outside the image or
  excluded), must cancel to nothing.

Why that suffices: with every volume positive, every element inside one leaf of the
labels and every included leaf filled to its volume (excluded leaves left empty), a
vanishing remainder means that the winding number of the single facets (the degree of
the mesh at a point) is constant between the image box and the excluded pixels, so 1:
the elements tile the included pixels exactly once. In a tiling every facet has at most
one element on each side, so none is shared by three, pairs are seen from opposite
sides and a single facet lies on the box or faces an excluded pixel: everything the
sort checks. The full check would pass, with zero counts.

The remainder is tested by a fingerprint: each vertex gets a fixed pseudo-random 64-bit
value ``x_v``, a facet ``{a, b, c}`` the product ``x_a x_b x_c`` (no sort of its ids:
the product is symmetric) with the sign of its orientation, and the sum over all facets,
in arithmetic modulo 2**64, is zero for a vanishing chain. A chain that does not vanish
is a polynomial that is not zero, and its value at random points is zero with
probability about 2**-60 (Schwartz-Zippel; a coefficient can be even, never a multiple of
2**60 here). When anything fails, nothing of this pass is reported: the caller runs the
general checks, whose counts say what is wrong.
"""

from __future__ import annotations

import math

import numpy as np

from ..._region_tree import RegionTree
from ..mesher._packed import pack_points, unpack
from ..model._quality import _edge_det

__all__ = ["lattice_checks"]

_CELLS_PER_CHUNK = 1 << 16
_SEED = 0x5EED_C4A1                  # fixed: the same mesh always gets the same verdict
_MASK = (1 << 64) - 1
_FINEST = 4                          # points at 1/16 pixel at most (--refine 4)


def _near_excluded(lab: np.ndarray, exclude: np.ndarray, leaf_map: np.ndarray,
                   n_leaves: int) -> np.ndarray:
    """(n_leaves,) bool: leaves with a pixel next to an excluded one (only their elements
    can have a facet facing one)."""
    flags = np.zeros(n_leaves, dtype=bool)
    if not exclude.size:
        return flags
    excluded = np.isin(lab, exclude)
    near = np.zeros(lab.shape, dtype=bool)
    for a in range(lab.ndim):
        lo = [slice(None)] * lab.ndim
        hi = [slice(None)] * lab.ndim
        lo[a], hi[a] = slice(0, -1), slice(1, None)
        near[tuple(lo)] |= excluded[tuple(hi)]
        near[tuple(hi)] |= excluded[tuple(lo)]
    near &= ~excluded
    flags[leaf_map.reshape(lab.shape)[near]] = True
    return flags


def lattice_checks(points: np.ndarray, cells: np.ndarray, material: np.ndarray,
                   lab: np.ndarray, exclude: np.ndarray, tree: RegionTree,
                   n_included: int) -> dict | None:
    """Every check's counts when a mesh in index space passes them all, else None.

    `points` in pixel units, `lab` the label image of the same space, `tree` its region
    tree, `n_included` its pixels not excluded. Returns the fields of ``MeshChecks``
    (volumes in pixel units; ``finite`` is the caller's) exactly as the general checks
    give them for a mesh that passes, or None when the points are not integers or some
    check fails (then the general checks say which and by how much).
    """
    d = lab.ndim
    m = len(cells)
    found, fine = None, 0
    while m and found is None and fine <= _FINEST:
        # points on a lattice 2**fine times finer than the pixels (--refine)
        found = pack_points(points * (1 << fine) if fine else points)
        fine += found is None
    # edges below 2**16: determinants exact in int64 and in the general path's floats
    if found is None or max(lab.shape) << fine > 1 << 16:
        return None
    packed, bits = found
    unit = (1 << d * fine) * math.factorial(d)         # det per pixel volume
    shape = lab.shape
    strides = [math.prod(shape[a + 1:]) for a in range(d)]
    leaf_map = tree.to_image(values=np.arange(len(tree)), fill=-1,
                             dtype=np.int32 if len(tree) < 2**31 else np.int64).reshape(-1)
    near = _near_excluded(lab, exclude, leaf_map, len(tree))
    lab_flat = lab.reshape(-1)
    # per vertex, its packed corner and its random value side by side (16 bytes): one
    # gather per corner brings both
    both = np.empty((len(points), 2), dtype=np.int64)
    both[:, 0] = packed
    both[:, 1] = np.random.default_rng(_SEED).integers(0, 1 << 64, size=len(points),
                                                       dtype=np.uint64).view(np.int64)
    corner_values = both.view(np.complex128).reshape(-1)   # (N,) corner, value as one
    del packed
    rest = [[j for j in range(d + 1) if j != k] for k in range(d + 1)]
    leaf_volume = np.zeros(len(tree))
    used = np.zeros(len(points), dtype=bool)
    min_det: int | None = None
    total, chain, off_box = 0, 0, 0
    for start in range(0, m, _CELLS_PER_CHUNK):
        ids = cells[start:start + _CELLS_PER_CHUNK]
        n = len(ids)
        used[ids] = True
        col = np.ascontiguousarray(ids.T)                # (d+1, n)
        gathered = corner_values[col].view(np.int64)     # (d+1, 2n): corner, value, ...
        p = unpack(gathered[:, 0::2], bits, d)
        det = _edge_det([[p[k][a] - p[0][a] for a in range(d)] for k in range(1, d + 1)])
        low = int(det.min())
        if low <= 0:
            return None
        min_det = low if min_det is None else min(min_det, low)
        total += int(det.sum())
        # bounding box in pixels: [min, max) per axis, so the pixels at its two far
        # corners are min and max - 1 (integer corners: the general path's floor/ceil)
        flat_lo = np.zeros(n, dtype=np.int64)
        flat_hi = np.zeros(n, dtype=np.int64)
        on_box = np.zeros(n, dtype=bool)
        for a in range(d):
            lo, hi = np.minimum(p[0][a], p[1][a]), np.maximum(p[0][a], p[1][a])
            for k in range(2, d + 1):
                np.minimum(lo, p[k][a], out=lo)
                np.maximum(hi, p[k][a], out=hi)
            if int(hi.max()) > shape[a] << fine:
                return None                              # an element outside the image
            on_box |= (lo == 0) | (hi == shape[a] << fine)
            hi -= 1                                      # >= lo: volumes are positive
            if fine:
                lo >>= fine
                hi >>= fine
            flat_lo += lo * strides[a]
            flat_hi += hi * strides[a]
        leaf = leaf_map[flat_lo]
        if (leaf != leaf_map[flat_hi]).any() or int(leaf.min()) < 0:
            return None
        if (material[start:start + n] != lab_flat[flat_lo]).any():
            return None
        first = int(leaf.min())
        part = np.bincount(leaf - first, weights=det / (1 << d * fine) / math.factorial(d))
        leaf_volume[first:first + len(part)] += part
        # the chain: facet k (without corner k) enters with sign (-1)^k times the parity
        # of its corners' order
        terms = _facet_products(list(gathered[:, 1::2].view(np.uint64)))
        del gathered
        greater = {(i, j): col[i] > col[j] for i in range(d + 1) for j in range(i + 1, d + 1)}
        odds = []
        for k in range(d + 1):
            pairs = [greater[pair] for pair in greater if k not in pair]
            odd = pairs[0] ^ pairs[1] ^ pairs[2] if d == 3 else pairs[0].copy()
            if k & 1:
                np.logical_not(odd, out=odd)
            # the sum less twice the negative terms (a dot with 0/1 is one pass; a
            # masked negation or sum took five times as long)
            chain += int(terms[k].sum(dtype=np.uint64)) - 2 * int(
                np.dot(terms[k], odd.astype(np.uint64)))
            odds.append(odd)
        # less the facets allowed to stay single, found among elements on the box or in
        # a leaf next to an excluded pixel
        cand = np.flatnonzero(on_box | near[leaf])
        for k in range(d + 1):
            if len(cand):
                single, exterior = _may_stay_single(
                    [[p[j][a][cand] for a in range(d)] for j in rest[k]],
                    [p[k][a][cand] for a in range(d)], lab, exclude, fine)
                single = cand[single]
                term = terms[k][single]
                np.negative(term, out=term, where=odds[k][single])
                chain -= int(term.sum(dtype=np.uint64))
                off_box += exterior
        chain &= _MASK
    if chain:
        return None
    size = tree.size ** d
    excluded = np.isin(tree.label, exclude) if exclude.size else False
    expected = np.where(tree.inside & ~excluded, size, 0)
    wrong_leaf = np.abs(leaf_volume - expected) > 1e-9 * np.maximum(size, 1)
    if (wrong_leaf & tree.inside).any():
        return None
    volume = total / unit
    if abs(volume - n_included) > 1e-9 * max(1, n_included):
        return None
    if min_det is None:  # pragma: no cover - no elements returned None above
        return None
    return {"min_volume": min_det / (1 << d * fine) / math.factorial(d),
            "positive_volume": True,
            "volume_error": volume - n_included, "volume_sum": True,
            "n_outside_leaf": 0, "inside_one_leaf": True,
            "n_pixels_wrong": 0, "labels_recovered": True,
            "n_unused_points": int(len(points) - np.count_nonzero(used)),
            "n_facets_shared_3plus": 0, "n_misoriented_facets": 0,
            "n_boundary_facets_off_box": off_box, "n_unmatched_facets": 0, "conforming": True}


def _facet_products(v: list) -> list:
    """``x`` products over each facet (the corners but k), modulo 2**64."""
    if len(v) == 3:
        return [v[1] * v[2], v[0] * v[2], v[0] * v[1]]
    ab, cd = v[0] * v[1], v[2] * v[3]
    return [v[1] * cd, v[0] * cd, ab * v[3], ab * v[2]]


def _may_stay_single(corners: list, opposite: list, lab: np.ndarray, exclude: np.ndarray,
                     fine: int = 0) -> tuple[np.ndarray, int]:
    """Which facets (their d corners ``corners[j][a]`` and the element's other corner
    ``opposite[a]``, integers in units of 2**-fine pixel) lie on a pixel plane with the
    pixel just across outside
    the image or excluded: the facets the general check lets stay single (its probe,
    a quarter pixel out of the facet's centroid, lands in that pixel), and how many of
    them face an excluded pixel (not the box)."""
    d = len(opposite)
    n = len(opposite[0])
    result = np.zeros(n, dtype=bool)
    exterior = 0
    for a in range(d):
        plane = corners[0][a]
        flat = np.ones(n, dtype=bool)
        for c in corners[1:]:
            flat &= c[a] == plane
        if fine:                       # inside a pixel: the pixel across is its own
            flat &= (plane & ((1 << fine) - 1)) == 0
        hit = np.flatnonzero(flat)
        if not len(hit):
            continue
        pixel_rows = []
        for b in range(d):
            if b == a:
                # the element lies above the plane: the pixel across is below it
                pixel_rows.append((plane[hit] >> fine) - (opposite[a][hit] > plane[hit]))
            else:
                pixel_rows.append(sum(c[b][hit] for c in corners) // d >> fine)
        pixel = np.stack(pixel_rows)
        inside = ((pixel >= 0) & (pixel < np.array(lab.shape)[:, None])).all(axis=0)
        ok = np.logical_not(inside)
        if exclude.size and inside.any():
            ok[inside] = facing = np.isin(lab[tuple(pixel[:, inside])], exclude)
            exterior += int(np.count_nonzero(facing))
        result[hit[ok]] = True
    return result, exterior
