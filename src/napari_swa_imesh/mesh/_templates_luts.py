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
* Two templates:

  - ``KUHN[d]`` (``(d!, d+1, d)``, coordinates in {0, 1}, unit = leaf side): a leaf with no
    site on its boundary is cut into the d! Kuhn simplices around its main diagonal
    (0,...,0)-(1,...,1); every face is then cut by the diagonal through its lowest corner.
  - Otherwise each (d-1)-face is triangulated on its own and every face simplex is coned
    to the leaf centre. A face's triangulation depends only on which of *its* sites are
    vertices, so the two leaves that share a face cut it the same way (conforming by
    construction). 2-D faces (edges) are split at the midpoint when it is a vertex. 3-D
    faces: four quadrants (each cut by the diagonal through its lowest corner) when the
    face centre is a vertex; a fan from a *new* face-centre vertex over the boundary
    segments when only edge midpoints are; else one diagonal through the lowest corner.

* ``FACE_LUT[d][f][case]`` is the ``(t, d+1, d)`` array of cone simplices for face ``f``
  (``FACES[d][f] = (axis, side)``, side 0 or 2 on the local lattice) whose sites present
  are the bits of ``case``, bit ``i`` = ``FACE_SITES[d][f][i]`` (an index into
  ``SITES[d]``). Cases the balanced tree cannot produce (a 3-D face centre without all four
  edge midpoints) are empty arrays.
* Template ids: ``0 .. d!-1`` are the Kuhn simplices; face simplices follow, numbered by
  ``FACE_TEMPLATE_ID[d][f][case]`` (first id of that case). ``TEMPLATES[d]`` holds every
  template simplex by id as float coordinates in units of the leaf side, so per-element
  quality is a table look-up.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

__all__ = ["FACES", "FACE_LUT", "FACE_SITES", "FACE_TEMPLATE_ID", "KUHN", "SITES", "TEMPLATES",
           "face_simplices", "kuhn_simplices", "orient"]


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


def _face_polygons(present: set[tuple[int, int]]) -> list[list[tuple[int, int]]]:
    """Triangles of a square face, local 2-D coordinates in {0,1,2}^2.

    `present` holds the face's sites that are vertices ((1,0), (2,1), (1,2), (0,1) edge
    midpoints; (1,1) the centre).
    """
    def diagonal(i, j, s):
        # the diagonal through the lowest corner (i, j); Kuhn's choice
        return [[(i, j), (i + s, j), (i + s, j + s)], [(i, j), (i + s, j + s), (i, j + s)]]

    if (1, 1) in present:
        return [t for i in (0, 1) for j in (0, 1) for t in diagonal(i, j, 1)]
    ring = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    ring = [p for p in ring if p in present or (p[0] != 1 and p[1] != 1)]
    if len(ring) == 4:
        return diagonal(0, 0, 2)
    # fan from a new vertex at the face centre over the boundary segments
    return [[(1, 1), ring[i], ring[(i + 1) % len(ring)]] for i in range(len(ring))]


def face_simplices(d: int, axis: int, side: int, present: set[tuple[int, ...]]) -> np.ndarray:
    """(t, d+1, d) int8: the face's simplices coned to the leaf centre, oriented.

    `present` holds the local lattice coordinates (d-tuples) of the face's sites that are
    vertices.
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
        faces = segs
    elif d == 3:
        present_2d = {tuple(p[a] for a in others) for p in present}
        faces = _face_polygons(present_2d)
    else:
        raise ValueError(f"templates exist for 2-D and 3-D leaves only; got d={d}.")
    out = [orient(np.array([lift(q) for q in f] + [centre])) for f in faces]
    return np.array(out, dtype=np.int8)


def _build(d: int):
    sites = _sites(d)
    faces = _faces(d)
    face_sites = _face_sites(d, sites)
    kuhn = kuhn_simplices(d)
    templates = [k.astype(float) for k in kuhn]
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
                simplices = face_simplices(d, axis, side, present)
            ids_f.append(len(templates))
            templates.extend(s.astype(float) / 2.0 for s in simplices)
            lut_f.append(simplices)
        lut.append(lut_f)
        ids.append(np.array(ids_f, dtype=np.int32))
    return sites, faces, face_sites, kuhn, lut, ids, np.array(templates)


SITES: dict[int, np.ndarray] = {}
FACES: dict[int, list[tuple[int, int]]] = {}
FACE_SITES: dict[int, list[list[int]]] = {}
KUHN: dict[int, np.ndarray] = {}
FACE_LUT: dict[int, list[list[np.ndarray]]] = {}
FACE_TEMPLATE_ID: dict[int, list[np.ndarray]] = {}
TEMPLATES: dict[int, np.ndarray] = {}
for _d in (2, 3):
    (SITES[_d], FACES[_d], FACE_SITES[_d], KUHN[_d], FACE_LUT[_d], FACE_TEMPLATE_ID[_d],
     TEMPLATES[_d]) = _build(_d)
    assert len(KUHN[_d]) == math.factorial(_d)
del _d
