"""Look-up tables of the template ("dictionary") mesher, 2-D and 3-D.

Convention
----------
* A leaf of side ``2h`` is described on its *local lattice* ``{0, 1, 2}^d`` (unit ``h``):
  corners have coordinates in {0, 2}, the centre is ``(1,)*d``. In an edge-balanced tree
  (faces and edges, see ``_balance.py``) every vertex on a leaf's boundary is a lattice
  point: a corner, an edge midpoint or (3-D) a face centre. The non-corner boundary points
  are the *sites*, listed in ``SITES[d]`` (2-D: 4 edge midpoints; 3-D: 12 edge midpoints,
  then 6 face centres). A leaf's *configuration* is the set of sites that are vertices.
* Axes are numpy's (plane, row, column). A simplex is a ``(d+1, d)`` array of local
  coordinates, ordered so its signed volume ``det(p1-p0, ..., pd-p0)`` is positive.
* Face diagonals. Every square (a plain face, or a quadrant of a face whose centre is a
  vertex) is cut by one diagonal chosen by a global rule of the square alone, so the
  leaves on both sides and a big face's quadrants agree with the small leaves' faces:

  - *lowest* (variant 0, 2-D and periodic 3-D meshes with an odd extent): the diagonal
    through the square's lowest corner (Kuhn's choice);
  - *parity* (3-D, variants 1 and 2): the diagonal through the corner ``c`` with
    ``sum(c / s)`` even (lattice coordinates, ``s`` the square's side). On a leaf those
    corners depend on the leaf's *parity* ``sum(origin / side) % 2`` (variant 1 even, 2
    odd); the quadrants of a face are cut alike on both (an X through the face centre).
    A translation by an even number of cells keeps the rule, so periodic meshes with
    even extents use it too.

* Two templates:

  - ``PLAIN[d][v]`` (coordinates in {0, 1}, unit = leaf side): a leaf with no site on its
    boundary. Variant 0 is ``KUHN[d]``, the d! Kuhn simplices around the main diagonal
    (0,...,0)-(1,...,1) (every face cut through its lowest corner); the parity variants
    are five tetrahedra: the regular one on the four even corners and one right-corner
    tetrahedron at each odd corner (every face cut through its even corners).
  - Otherwise each (d-1)-face is triangulated on its own and every face simplex is coned
    to the leaf centre. A face's triangulation depends only on which of *its* sites are
    vertices (and the square's own parity), so the two leaves that share a face cut it
    the same way (conforming by construction). 2-D faces (edges) are split at the
    midpoint when it is a vertex. 3-D faces: four quadrants, each cut by the rule's
    diagonal, when the face centre is a vertex; a fan from a *new* face-centre vertex
    over the boundary segments when only edge midpoints are; else the rule's diagonal.

* Sited 3-D leaves under the parity rule whose cones can be beaten: ``LEAF_TABLE[3]``
  (:class:`LeafTable`, loaded from ``leaf_tables.npz`` beside this module) cuts them
  into the fewest tetrahedra with the same boundary triangles (so neighbours still agree),
  each within the bounds of the plain and cone templates, found offline by
  ``tools/leaf_tables.py`` and checked by ``tests/mesh/test_leaf_tables.py``. Other
  configurations, and every leaf of the lowest-corner rule, keep the cones.
* ``VARIANTS[d]``: the variants of that dimension (``(0,)`` in 2-D, ``(0, 1, 2)`` in 3-D).
  ``FACE_LUT[d][v][f][case]`` is the ``(t, d+1, d)`` array of cone simplices for face ``f``
  (``FACES[d][f] = (axis, side)``, side 0 or 2 on the local lattice) whose sites present
  are the bits of ``case``, bit ``i`` = ``FACE_SITES[d][f][i]`` (an index into
  ``SITES[d]``). Cases the balanced tree cannot produce (a 3-D face centre without all four
  edge midpoints) are empty arrays.
* Template ids: per variant, its plain simplices (first id ``PLAIN_TEMPLATE_ID[d][v]``;
  ``0 .. d!-1`` are the Kuhn simplices) then its face simplices, numbered by
  ``FACE_TEMPLATE_ID[d][v][f][case]`` (first id of that case). ``TEMPLATES[d]`` holds
  every template simplex by id as float coordinates in units of the leaf side, so
  per-element quality is a table look-up; the leaf table's simplices come last, from
  ``TABLE_FIRST_ID[3]``.
"""

from __future__ import annotations

import itertools
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["FACES", "FACE_LUT", "FACE_SITES", "FACE_TEMPLATE_ID", "KUHN", "LEAF_TABLE",
           "LeafTable", "PLAIN", "PLAIN_TEMPLATE_ID", "SITES", "TABLE_FIRST_ID", "TEMPLATES",
           "VARIANTS", "face_simplices",
           "kuhn_simplices", "orient", "parity_simplices"]


def orient(simplex: np.ndarray) -> np.ndarray:
    """Return `simplex` ((d+1, d) coordinates) reordered to positive signed volume."""
    simplex = np.asarray(simplex)
    det = np.linalg.det((simplex[1:] - simplex[0]).astype(float))
    if det == 0:
        raise ValueError(f"template simplex {simplex.tolist()} is degenerate.")
    if det < 0:
        simplex = simplex[[1, 0] + list(range(2, len(simplex)))]
    return simplex


def kuhn_simplices(d: int) -> np.ndarray:
    """(d!, d+1, d) int8: Kuhn's simplices of the unit cube, positively oriented."""
    out = []
    for perm in itertools.permutations(range(d)):
        path = [np.zeros(d, np.int8)]
        for axis in perm:
            nxt = path[-1].copy()
            nxt[axis] = 1
            path.append(nxt)
        out.append(orient(np.array(path)))
    return np.array(out, dtype=np.int8)


def parity_simplices(parity: int) -> np.ndarray:
    """(5, 4, 3) int8: the unit cube cut into five tetrahedra, positively oriented.

    The regular tetrahedron on the corners ``c`` with ``(sum(c) + parity)`` even and a
    right-corner tetrahedron at each other corner (its three cube neighbours); every face
    is cut by the diagonal through its two corners of the regular one.
    """
    corners = np.array(list(itertools.product((0, 1), repeat=3)), dtype=np.int8)
    even = (corners.sum(axis=1) + parity) % 2 == 0
    out = [orient(corners[even])]
    for c in corners[~even]:
        out.append(orient(np.array([c] + [c ^ np.eye(3, dtype=np.int8)[a] for a in range(3)])))
    return np.array(out, dtype=np.int8)


def _sites(d: int) -> np.ndarray:
    """Local lattice points on the boundary that are neither corners nor the centre."""
    pts = [p for p in itertools.product((0, 1, 2), repeat=d)
           if 0 < sum(c == 1 for c in p) < d]
    # edge midpoints first (one coordinate 1), then face centres (two coordinates 1)
    pts.sort(key=lambda p: (sum(c == 1 for c in p), p))
    return np.array(pts, dtype=np.int8)


def _faces(d: int) -> list[tuple[int, int]]:
    return [(axis, side) for axis in range(d) for side in (0, 2)]


def _face_sites(d: int, sites: np.ndarray) -> list[list[int]]:
    """For each face, the indices (into `sites`) of the sites on that face."""
    return [[i for i, p in enumerate(sites) if p[axis] == side] for axis, side in _faces(d)]


def _face_polygons(present: set[tuple[int, int]], through_low) -> list[list[tuple[int, int]]]:
    """Triangles of a square face, local 2-D coordinates in {0,1,2}^2.

    `present` holds the face's sites that are vertices ((1,0), (2,1), (1,2), (0,1) edge
    midpoints; (1,1) the centre). ``through_low(i, j, s)`` says whether the square of
    side `s` at (i, j) is cut by the diagonal through (i, j) (else through (i+s, j)).
    """
    def diagonal(i, j, s):
        if through_low(i, j, s):
            return [[(i, j), (i + s, j), (i + s, j + s)], [(i, j), (i + s, j + s), (i, j + s)]]
        return [[(i + s, j), (i + s, j + s), (i, j + s)], [(i + s, j), (i, j + s), (i, j)]]

    if (1, 1) in present:
        return [t for i in (0, 1) for j in (0, 1) for t in diagonal(i, j, 1)]
    ring = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    ring = [p for p in ring if p in present or (p[0] != 1 and p[1] != 1)]
    if len(ring) == 4:
        return diagonal(0, 0, 2)
    # fan from a new vertex at the face centre over the boundary segments
    return [[(1, 1), ring[i], ring[(i + 1) % len(ring)]] for i in range(len(ring))]


def face_simplices(d: int, axis: int, side: int, present: set[tuple[int, ...]],
                   variant: int = 0) -> np.ndarray:
    """(t, d+1, d) int8: the face's simplices coned to the leaf centre, oriented.

    `present` holds the local lattice coordinates (d-tuples) of the face's sites that are
    vertices; `variant` the diagonal rule (module docstring).
    """
    others = [a for a in range(d) if a != axis]
    centre = (1,) * d

    def lift(face_pt):
        p = [0] * d
        p[axis] = side
        for a, c in zip(others, face_pt):
            p[a] = c
        return tuple(p)

    if d == 2:
        mid = lift((1,))
        segs = [[(0,), (1,)], [(1,), (2,)]] if mid in present else [[(0,), (2,)]]
        faces: Sequence[Sequence[tuple[int, ...]]] = segs
    elif d == 3:
        present_2d = {(p[others[0]], p[others[1]]) for p in present}

        def through_low(i, j, s):
            if variant == 0:
                return True
            # parity of the corner in units of the square's side: the leaf's parity
            # counts for a whole face (s = 2), not for a quadrant (s = 1)
            total = sum(lift((i, j))) // s + (variant - 1) * (s == 2)
            return total % 2 == 0

        faces = _face_polygons(present_2d, through_low)
    else:
        raise ValueError(f"templates exist for 2-D and 3-D leaves only; got d={d}.")
    flat = np.array(faces, dtype=np.int8)                     # (t, d, d-1) face coordinates
    out = np.empty((len(flat), d + 1, d), dtype=np.int8)
    out[:, :d, axis] = side
    out[:, :d, others] = flat
    out[:, d] = centre
    # orient all at once (one determinant call, not one per simplex: import time)
    det = np.linalg.det((out[:, 1:] - out[:, :1]).astype(float))
    if (det == 0).any():
        raise ValueError("a template simplex is degenerate.")
    out[det < 0, :2] = out[det < 0, 1::-1]
    return out


def _build_variant(d: int, v: int, sites, faces, face_sites, templates: list):
    plain = kuhn_simplices(d) if v == 0 else parity_simplices(v - 1)
    plain_id = len(templates)
    templates.extend(k.astype(float) for k in plain)
    lut, ids = [], []
    for (axis, side), fsites in zip(faces, face_sites):
        lut_f, ids_f = [], []
        for case in range(1 << len(fsites)):
            present = {tuple(int(c) for c in sites[s]) for i, s in enumerate(fsites)
                       if case >> i & 1}
            centre_2d = d == 3 and any(sum(c == 1 for c in p) == 2 for p in present)
            if centre_2d and len(present) != len(fsites):
                simplices = np.zeros((0, d + 1, d), np.int8)  # not produced by the tree
            else:
                simplices = face_simplices(d, axis, side, present, v)
            ids_f.append(len(templates))
            templates.extend(s.astype(float) / 2.0 for s in simplices)
            lut_f.append(simplices)
        lut.append(lut_f)
        ids.append(np.array(ids_f, dtype=np.int32))
    return plain, plain_id, lut, ids


def _build(d: int):
    sites = _sites(d)
    faces = _faces(d)
    face_sites = _face_sites(d, sites)
    templates: list = []
    plain: list[np.ndarray] = []                    # one entry per diagonal variant
    plain_id: list[int] = []
    lut: list[list[list[np.ndarray]]] = []
    ids: list[list[np.ndarray]] = []
    for v in (0,) if d == 2 else (0, 1, 2):
        v_plain, v_plain_id, v_lut, v_ids = _build_variant(d, v, sites, faces, face_sites,
                                                           templates)
        plain.append(v_plain)
        plain_id.append(v_plain_id)
        lut.append(v_lut)
        ids.append(v_ids)
    return sites, faces, face_sites, plain, plain_id, lut, ids, np.array(templates)


SITES: dict[int, np.ndarray] = {}
FACES: dict[int, list[tuple[int, int]]] = {}
FACE_SITES: dict[int, list[list[int]]] = {}
KUHN: dict[int, np.ndarray] = {}
PLAIN: dict[int, list[np.ndarray]] = {}
PLAIN_TEMPLATE_ID: dict[int, list[int]] = {}
FACE_LUT: dict[int, list[list[list[np.ndarray]]]] = {}
FACE_TEMPLATE_ID: dict[int, list[list[np.ndarray]]] = {}
TEMPLATES: dict[int, np.ndarray] = {}
for _d in (2, 3):
    (SITES[_d], FACES[_d], FACE_SITES[_d], PLAIN[_d], PLAIN_TEMPLATE_ID[_d], FACE_LUT[_d],
     FACE_TEMPLATE_ID[_d], TEMPLATES[_d]) = _build(_d)
    KUHN[_d] = PLAIN[_d][0]
    assert len(KUHN[_d]) == math.factorial(_d)
del _d
VARIANTS: dict[int, tuple[int, ...]] = {d: tuple(range(len(PLAIN[d]))) for d in PLAIN}
#: id of the first sited-leaf table simplex: the plain and cone templates come before
TABLE_FIRST_ID: dict[int, int] = {d: len(TEMPLATES[d]) for d in TEMPLATES}


@dataclass(frozen=True, eq=False)  # hashed by identity: look-ups cache per table
class LeafTable:
    """Sited 3-D leaves cut into fewer tetrahedra than the cones, per configuration.

    Made offline by ``tools/leaf_tables.py`` (a MILP per configuration class, the face
    triangulations of ``FACE_LUT`` kept) and checked by ``tests/mesh/test_leaf_tables.py``.
    Entry ``e`` is the leaf of variant ``key[e] >> 18`` whose sites present are the bits
    of ``key[e] & (2**18 - 1)`` (bit i = ``SITES[3][i]``); its tetrahedra are
    ``simplex[member[offset[e]:offset[e + 1]]]`` (local coordinates in {0, 1, 2}, unit
    half the leaf side, positively oriented; template id ``TABLE_FIRST_ID[3] + member``).
    ``new[e]`` lists (lattice indices ``9x + 3y + z``) the points the entry uses that are
    neither corners nor sites present: fan face centres, and the leaf centre if used.
    """

    key: np.ndarray          # (K,) int32, sorted
    offset: np.ndarray       # (K+1,) int64
    member: np.ndarray       # (T,) int16
    simplex: np.ndarray      # (S, 4, 3) int8
    new_entry: np.ndarray    # (N,) int64: entry of each new point
    new_point: np.ndarray    # (N, 3) int8: local coordinates of each new point

    @property
    def member_rows(self) -> np.ndarray:
        """(K, t_max) int16: each entry's members in one row, padded with -1."""
        count = np.diff(self.offset)
        rows = np.full((len(self.key), int(count.max(initial=0))), -1, dtype=np.int16)
        rows[np.repeat(np.arange(len(self.key)), count),
             np.arange(len(self.member)) - np.repeat(self.offset[:-1], count)] = self.member
        return rows


def _load_table(path: Path) -> LeafTable | None:
    if not path.exists():
        return None
    with np.load(path) as z:
        return LeafTable(z["key"].astype(np.int32), z["offset"].astype(np.int64),
                         z["member"].astype(np.int16), z["simplex"].astype(np.int8),
                         z["new_entry"].astype(np.int64), z["new_point"].astype(np.int8))


def table_new_points(key: np.ndarray, offset: np.ndarray, member: np.ndarray,
                     simplex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(entry, local point) of every point a table entry uses that is neither a corner
    nor a site present: what :class:`LeafTable` stores as ``new_entry``, ``new_point``."""
    lattice = np.array(list(itertools.product((0, 1, 2), repeat=3)), dtype=np.int8)
    used = np.zeros((len(key), 27), dtype=bool)
    entry_of = np.repeat(np.arange(len(key)), np.diff(offset))
    idx = (simplex.astype(np.int64) * np.array([9, 3, 1])).sum(axis=2)[member]  # (T, 4)
    used[entry_of[:, None], idx] = True
    used[:, (lattice == 1).sum(axis=1) == 0] = False                      # corners
    site_idx = SITES[3].astype(np.int64) @ np.array([9, 3, 1])
    present = (key[:, None] >> np.arange(len(site_idx))) & 1
    used[:, site_idx] &= present == 0
    new_entry, new_idx = np.nonzero(used)
    return new_entry.astype(np.int64), lattice[new_idx]


class _LoadedOnFirstRead(dict):
    """A dict that first loads ``leaf_tables.npz`` (:func:`_load_leaf_tables`) when read."""

    def __getitem__(self, key):
        _load_leaf_tables()
        return super().__getitem__(key)

    def get(self, key, default=None):
        _load_leaf_tables()
        return super().get(key, default)

    def __contains__(self, key):
        _load_leaf_tables()
        return super().__contains__(key)


_LEAF_LOCK = threading.Lock()
_leaf_tables_loaded = False


def _load_leaf_tables() -> None:
    """Add the 3-D leaf table to :data:`LEAF_TABLE` and its simplices to ``TEMPLATES[3]``,
    once, on the first read of either (not at import: ``import`` stays cheap)."""
    global _leaf_tables_loaded
    if _leaf_tables_loaded:
        return
    with _LEAF_LOCK:
        if _leaf_tables_loaded:
            return
        table = _load_table(Path(__file__).with_name("leaf_tables.npz"))
        if table is not None:
            dict.__setitem__(LEAF_TABLE, 3, table)
            dict.__setitem__(TEMPLATES, 3, np.concatenate(
                [dict.__getitem__(TEMPLATES, 3), table.simplex.astype(float) / 2.0]))
        _leaf_tables_loaded = True


LEAF_TABLE: dict[int, LeafTable] = _LoadedOnFirstRead()
TEMPLATES = _LoadedOnFirstRead(TEMPLATES)
