"""The facets of the facet groups of a template mesh, found leaf by leaf without a sort.

A template mesh cuts every leaf of a balanced 2^d-tree on its own, so a material
interface or a boundary can only run along leaf faces, and every element lies in the
leaf its ``cell_data["leaf"]`` names (``level`` gives the side, ``2**level`` lattice
cells). Then a facet belongs to a group exactly when it lies on a face of its element's
leaf and the lattice cell just across that face is outside the image (a box side), not
meshed (an exterior) or of another material (an interface). Painting each leaf's material
into one lattice-sized image and probing it once per element facet finds them all, each
interface once from its lower material's side, in one pass over the elements: no sort
of the ``(d+1) * M`` facet occurrences (the general path of ``_facets``), which cost
several times the meshing at volume size.

Only meshes the template mesher made qualify (:func:`template_group_rows` returns None
for the rest, and the caller takes the general path): a ``recipe`` of method
``"template"`` (a mesh built from arrays, cut down or given new arrays has none), points
on the lattice, and the two sides of every interface counted alike. A lattice of more
than 16 cells per element (deep ``--refine`` on a coarse mesh) is not painted either.
"""

from __future__ import annotations

import math

import numpy as np

from ..mesher._lattice import Lattice
from ..mesher._packed import corners, pack_points
from ..model._quality import _edge_det
from ..model._recipe import MadeLattice
from ..model._types import Mesh

__all__ = ["material_codes", "present_materials", "template_group_rows"]

_CHUNK = 1 << 17                  # elements per pass (their corners stay in cache-ish)
_PAINT = 1 << 22                  # lattice cells painted at once
_BIG_LEAF = 1 << 12               # leaves of more lattice cells are painted one by one
_MAX_CELLS_PER_ELEMENT = 16       # a bigger lattice image (deep --refine) is not worth it
OUTSIDE, EMPTY = -2, -1           # probe results: beyond the image box, no element there
#: face bit (2a: low end of axis a, 2a+1: high end) -> axis, and the step out of the leaf
#: to the lattice cell across (-1 below the low end, 0 from the high end)
_FACE_AXIS = np.zeros(64, dtype=np.int8)
_FACE_STEP = np.zeros(64, dtype=np.int64)
for _bit in range(6):
    _FACE_AXIS[1 << _bit], _FACE_STEP[1 << _bit] = _bit // 2, -1 + (_bit & 1)


def present_materials(material: np.ndarray) -> np.ndarray:
    """The materials present, sorted: :func:`material_codes` without the per-element
    ranks (a gather of every element that callers wanting only the list skip).

    Examples
    --------
    >>> present_materials(np.array([7, 2, 7])).tolist()
    [2, 7]
    """
    material = np.asarray(material)
    top = int(material.max()) if material.size else 0
    if material.size and material.min() >= 0 and top < max(1 << 20, material.size):
        return np.flatnonzero(np.bincount(material, minlength=top + 1)).astype(material.dtype)
    return np.unique(material)


def material_codes(material: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The materials present (sorted) and each element's rank among them (int16 when
    they fit): a look-up table for label-sized ids, since a sort of tens of millions of
    elements takes seconds.

    Examples
    --------
    >>> materials, code = material_codes(np.array([7, 2, 7]))
    >>> materials.tolist(), code.tolist()
    ([2, 7], [1, 0, 1])
    """
    material = np.asarray(material)
    top = int(material.max()) if material.size else 0
    if material.size and material.min() >= 0 and top < max(1 << 20, material.size):
        present = np.bincount(material, minlength=top + 1) > 0
        materials = np.flatnonzero(present).astype(material.dtype)
        rank = np.cumsum(present) - 1
        dtype = np.int16 if len(materials) < 2**15 else np.int64
        return materials, rank.astype(dtype)[material]
    materials, code = np.unique(material, return_inverse=True)
    return materials, code.reshape(-1).astype(np.int16 if len(materials) < 2**15 else np.int64)


def _as_made(mesh: Mesh) -> MadeLattice | None:
    """``mesh.made`` while the mesh holds the arrays it was made for, else None."""
    made = mesh.made
    return made if made is not None and made.applies_to(mesh) else None


def _lattice_shape(mesh: Mesh, lattice: Lattice | None) -> tuple[int, ...] | None:
    """The shape of the lattice of cells the mesh records (its recipe's `lattice`, None
    for the voxels), or None."""
    step = np.asarray(mesh.spacing if lattice is None else lattice.step, dtype=np.float64)
    per_voxel = np.asarray([1] * mesh.ndim if lattice is None else lattice.cells_per_voxel,
                           dtype=np.int64)
    if step.shape != (mesh.ndim,) or per_voxel.shape != (mesh.ndim,):
        return None
    shape = tuple(int(n) for n in np.asarray(mesh.shape, dtype=np.int64) * per_voxel)
    return shape if len(shape) == mesh.ndim and max(shape) < 2**30 else None


def _lattice_coords(mesh: Mesh, lattice: Lattice | None) -> np.ndarray | None:
    """Vertex coordinates in lattice cells (int32), or None when the points are not on
    the lattice the mesh records (its recipe's `lattice`, None for the voxels)."""
    u = mesh.points / np.asarray(mesh.spacing if lattice is None else lattice.step,
                                 dtype=np.float64)
    coords = np.rint(u).astype(np.int32)
    u -= coords
    if not len(u) or np.abs(u, out=u).max() > 1e-6:
        return None
    return coords


def _leaf_boxes(packed, axes, cells, leaf, level, shape, leaf_origin=None):
    """One element of each leaf (any), the leaf's lowest corner and level; None when a
    leaf leaves the lattice. Leaves are aligned to their side, and a simplex of positive
    volume has a corner below the leaf's far faces: the lowest corner, rounded down
    (unless the mesher's `leaf_origin` of every leaf id is given)."""
    if (leaf[1:] >= leaf[:-1]).all():     # the mesher's order: the last of each run
        rep = np.flatnonzero(np.append(leaf[1:] != leaf[:-1], True))
    else:                                  # the last of each leaf, as a scatter leaves it
        rep = np.full(int(leaf.max()) + 1, -1, dtype=np.int64)
        rep[leaf] = np.arange(len(leaf))
        rep = rep[rep >= 0]
    lev = level[rep]
    shift = lev.astype(np.int64)
    if leaf_origin is not None:
        origin = leaf_origin[leaf[rep]].astype(np.int64)
    else:
        p = _gather(packed, axes, cells[rep], len(shape))
        origin = np.stack([(np.minimum.reduce([c[a] for c in p]).astype(np.int64) >> shift)
                           << shift for a in range(len(shape))], axis=1)
    if (origin < 0).any() or ((origin + (1 << shift)[:, None]) > np.asarray(shape)).any():
        return None
    return rep, origin, lev


def _paint(boxes, values, shape, dtype) -> np.ndarray:
    """Flat lattice image of the leaves' `values` (EMPTY where no leaf was meshed)."""
    d = len(shape)
    image = np.full(math.prod(shape), EMPTY, dtype=dtype)
    _, origin, lev = boxes
    strides = np.array([math.prod(shape[a + 1:]) for a in range(d)], dtype=np.int64)
    okey = origin @ strides
    box = image.reshape(shape)
    for lv in np.unique(lev):
        sel = np.flatnonzero(lev == lv)
        side = 1 << int(lv)
        if side ** d > _BIG_LEAF:
            # big leaves are few (the volume over their size): a block each
            for i in sel:
                box[tuple(slice(o, o + side) for o in origin[i])] = values[i]
            continue
        offsets = np.indices((side,) * d).reshape(d, -1).T.astype(np.int64) @ strides
        step = max(1, _PAINT // len(offsets))
        for s in range(0, len(sel), step):
            part = sel[s:s + step]
            image[(okey[part, None] + offsets[None]).ravel()] = np.repeat(values[part],
                                                                          len(offsets))
    return image


def _on_group_faces(image: np.ndarray, shape, boxes) -> np.ndarray:
    """Which leaves hold a lattice cell next to another value of `image` or to the image
    box (a summed-area table of those cells, read at each leaf's 2**d corners)."""
    d = len(shape)
    box = image.reshape(shape)
    edge = np.zeros(shape, dtype=bool)
    for a in range(d):
        lo = (slice(None),) * a + (slice(0, -1),)
        hi = (slice(None),) * a + (slice(1, None),)
        differ = box[lo] != box[hi]
        edge[lo] |= differ
        edge[hi] |= differ
        edge[(slice(None),) * a + (0,)] = True
        edge[(slice(None),) * a + (-1,)] = True
    dtype = np.int32 if math.prod(shape) < 2**31 else np.int64
    table = np.zeros(tuple(n + 1 for n in shape), dtype=dtype)
    table[(slice(1, None),) * d] = edge
    del edge
    for a in range(d):
        np.cumsum(table, axis=a, dtype=dtype, out=table)
    _, origin, lev = boxes
    far = origin + (1 << lev.astype(np.int64))[:, None]
    count = np.zeros(len(origin), dtype=np.int64)
    for corner in range(1 << d):
        ends = [far[:, a] if corner >> a & 1 else origin[:, a] for a in range(d)]
        sign = -1 if (d - bin(corner).count("1")) & 1 else 1
        count += sign * table[tuple(ends)]
    return count > 0


def _gather(packed, axes, cells, d) -> list:
    """``p[corner][axis]`` of `cells`: unpacked, or axis by axis when the points did not
    pack."""
    if packed is not None:
        return corners(packed[0], cells, packed[1], d, np.int32)
    return [[x[cells[:, j]] for x in axes] for j in range(d + 1)]


def _lattice_det(p: list) -> np.ndarray:
    """Det of int32 lattice corners ``p[k][a]``, exact: in int32 when no edge is longer than
    2**9 (each of the six products then below 2**27, their sum below 2**30; no casts),
    else in int64. Edges are exact in int32: coordinates lie in [0, 2**30)."""
    e = [[p[k][a] - p[0][a] for a in range(len(p[0]))] for k in range(1, len(p))]
    if max(max(int(x.max()), -int(x.min())) for row in e for x in row) > 1 << 9:
        e = [[x.astype(np.int64) for x in row] for row in e]
    return _edge_det(e)


def template_group_rows(mesh: Mesh, *, signs: bool = False):
    """The group facets of a template mesh as (owner, opposite, across), or None.

    With `signs`, a fourth array: (M,) bool, which elements have a negative volume (in
    the lattice, whose axes are the points' scaled by positive steps), from the corners
    this pass gathers anyway.

    Returns
    -------
    owner : (F,) ndarray of intp
        The element each group facet bounds: the only one on the boundary, the one of
        the lower material on an interface.
    opposite : (F,) ndarray of intp
        The owner's corner opposite the facet.
    across : (F,) ndarray of int64
        What lies across: the material on the other side of an interface, ``OUTSIDE`` on
        a side of the image box, ``EMPTY`` next to a material left out of the mesh.

    None when `mesh` is not one the template mesher made as it made it (see the module
    docstring); the facets then have to be paired by sorting.
    """
    recipe, cd = mesh.recipe, mesh.cell_data
    m, d = mesh.n_cells, mesh.ndim
    if (recipe is None or recipe.method != "template" or "leaf" not in cd
            or "level" not in cd or not mesh.records_box or m == 0 or d not in (2, 3)):
        return None
    shape = _lattice_shape(mesh, recipe.lattice)
    if shape is None or math.prod(shape) > _MAX_CELLS_PER_ELEMENT * m + (1 << 20):
        return None
    made = _as_made(mesh)
    packed: tuple[np.ndarray, int] | None
    axes: list[np.ndarray]
    if made is not None and made.packed is not None:
        packed, axes = made.packed, []
    else:
        made, coords = None, _lattice_coords(mesh, recipe.lattice)
        if coords is None:
            return None
        packed = pack_points(coords)
        axes = [np.ascontiguousarray(coords[:, a]) for a in range(d)] if packed is None else []
        del coords
    materials, code = material_codes(mesh.material)
    dtype = code.dtype
    cells, leaf, level = mesh.cells, cd["leaf"], cd["level"]
    boxes = _leaf_boxes(packed, axes, cells, leaf, level, shape,
                        None if made is None else made.leaf_origin)
    if boxes is None:
        return None
    leaf_code = code[boxes[0]]
    image = _paint(boxes, leaf_code, shape, dtype)
    # only elements of a leaf with a group facet, or of a material not its leaf's, can
    # own one: the others (most, inside their material) skip the facet work
    worth = np.zeros(int(leaf.max()) + 1, dtype=bool)
    worth[leaf[boxes[0]]] = _on_group_faces(image, shape, boxes)
    leaf_code_of = np.zeros(len(worth), dtype=dtype)
    leaf_code_of[leaf[boxes[0]]] = leaf_code
    del boxes
    bound = np.asarray(shape, dtype=np.int64)
    strides = np.array([math.prod(shape[a + 1:]) for a in range(d)], dtype=np.int64)
    owners, opposites, acrosses = [], [], []
    n_pairs = len(materials) ** 2
    seen_from_a = np.zeros(n_pairs, dtype=np.int64)
    seen_from_b = np.zeros(n_pairs, dtype=np.int64)
    negative = np.zeros(m if signs else 0, dtype=bool)
    # a mesh as made has none negative: then only group elements are read
    sign_pass = signs and made is None
    for start in range(0, m, _CHUNK):
        cc = cells[start:start + _CHUNK]
        n = len(cc)
        lf = leaf[start:start + _CHUNK]
        sel = np.flatnonzero(worth[lf] | (code[start:start + n] != leaf_code_of[lf]))
        if sign_pass:
            p = _gather(packed, axes, cc, d)
            np.less(_lattice_det(p), 0, out=negative[start:start + n])
            p = [[x[sel] for x in row] for row in p]
        else:
            p = _gather(packed, axes, cc[sel], d)
        n = len(sel)
        if not n:
            continue
        shift = level[start:start + _CHUNK][sel].astype(np.int32)
        # which faces of its leaf (aligned to its side) each corner lies on: bit 2a for
        # the low end along axis a, bit 2a+1 for the high end
        faces = [np.zeros(n, dtype=np.uint8) for _ in range(d + 1)]
        for a in range(d):
            lo = p[0][a].copy()
            for j in range(1, d + 1):
                np.minimum(lo, p[j][a], out=lo)
            lo >>= shift
            lo <<= shift
            hi = lo + (np.int32(1) << shift)
            for j in range(d + 1):
                faces[j] |= (p[j][a] == lo).view(np.uint8) << np.uint8(2 * a)
                faces[j] |= (p[j][a] == hi).view(np.uint8) << np.uint8(2 * a + 1)
        for k in range(d + 1):
            rest = [j for j in range(d + 1) if j != k]
            # the face the facet lies on (the bits all its corners share: one at most)
            shared = faces[rest[0]].copy()
            for j in rest[1:]:
                shared &= faces[j]
            hit = np.flatnonzero(shared)
            if not len(hit):
                continue
            bits = shared[hit]
            if (bits & (bits - 1)).any():        # on two faces: a flat facet, not ours
                return None
            ax, out = _FACE_AXIS[bits], _FACE_STEP[bits]
            # the lattice cell across the face: one step out along the face's axis, the
            # facet's lowest corner along the others (the facet has an extent along
            # each, and its box lies in one neighbour's face: the templates cut a face
            # as its smaller neighbours do)
            flat = np.zeros(len(hit), dtype=np.int64)
            inside = np.ones(len(hit), dtype=bool)
            for a in range(d):
                first = p[rest[0]][a][hit].astype(np.int64)
                low = first.copy()
                for j in rest[1:]:
                    np.minimum(low, p[j][a][hit], out=low)
                cell = np.where(ax == a, first + out, low)
                inside &= (cell >= 0) & (cell < bound[a])
                flat += cell * strides[a]
            across = np.full(len(hit), OUTSIDE, dtype=np.int64)
            across[inside] = image[flat[inside]]
            hit = sel[hit]                   # the facets' elements in the chunk
            mine = code[start + hit].astype(np.int64)
            differ = across != mine
            hit, across, mine = hit[differ], across[differ], mine[differ]
            other = across >= 0
            lower = ~other | (mine < across)
            # both sides of each interface, counted, must agree (a cheap guard)
            pair = np.minimum(mine, across) * len(materials) + np.maximum(mine, across)
            seen_from_a += np.bincount(pair[other & lower], minlength=n_pairs)
            seen_from_b += np.bincount(pair[other & ~lower], minlength=n_pairs)
            owners.append(start + hit[lower])
            opposites.append(np.full(int(lower.sum()), k, dtype=np.intp))
            acrosses.append(np.where(other[lower], materials[np.maximum(across[lower], 0)],
                                     across[lower]))
    if not np.array_equal(seen_from_a, seen_from_b):
        return None
    rows = ((np.concatenate(owners).astype(np.intp), np.concatenate(opposites),
             np.concatenate(acrosses).astype(np.int64)) if owners
            else (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.int64)))
    return (*rows, negative) if signs else rows
