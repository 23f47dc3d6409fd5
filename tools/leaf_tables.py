"""Generate the sited-leaf tables of the template mesher (``mesh/mesher/leaf_tables.npz``).

Run:  python tools/leaf_tables.py [--time-limit SECONDS] [--out PATH]

A 3-D leaf with a site on its boundary is cut by coning each face triangle to its centre
(``_templates_luts``): one tetrahedron per boundary triangle, 12 to 48. With the face
triangulations kept as they are (so neighbours still agree and conformity holds by
construction), the inside of the leaf may be cut into fewer tetrahedra. For every leaf
configuration under both parity rules (variants 1 and 2; the lowest-corner variant 0 of
periodic meshes with an odd extent keeps the cones), this script solves offline, with
``scipy.optimize.milp``, for the fewest tetrahedra that

* have their corners among the leaf's points (corners, sites present, the new face
  centres of fans) and optionally the leaf centre, no other of those points in them;
* are each within the mesher's proven quality bounds, also stretched by any cell shape
  of a grid of aspects up to 8 (so no bound the package states, cubic, per residual
  aspect or for stretched voxels, gets worse);
* cover every boundary triangle of the face look-up table once, no other triangle on the
  leaf's faces, every inner triangle as often from each side, and sum to the leaf's
  volume (then they tile the leaf face to face: a conforming triangulation).

Configurations are solved once per class under the cube's 48 symmetries (a reflection of
an odd number of axes swaps the two parity variants) and mapped back. Each solution is
kept by the symmetries that fix its configuration (a constraint of the MILP), so the
table commutes with the cube's symmetries: a transposed image gets the transposed mesh,
as with Kuhn's and the cones' templates. Every stored
triangulation is then verified on its own (facets against the face table, volumes,
quality). Only configurations the solver cuts into fewer tetrahedra than the cones are
stored. The package test ``tests/mesh/test_leaf_tables.py`` checks the stored file again,
independently of this script.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import coo_matrix

from napari_swa_imesh.mesh.mesher import _templates_luts as luts
from napari_swa_imesh.mesh.model._bounds import leaf_configurations
from napari_swa_imesh.mesh.model._quality import quality_data

D = 3
VARIANTS = (1, 2)
LATTICE = np.array(list(itertools.product((0, 1, 2), repeat=3)), dtype=np.int64)  # 9x+3y+z
CENTRE = 13
EPS = 1e-9
#: cell shapes (1, b, c) every candidate is checked under, beside the cube
GRID = (1 / 8, 1 / 6, 1 / 4, 1 / 3, 1 / 2, 2 / 3, 0.8, 1 / 1.2, 0.9, 1.0, 1.1, 1.2, 1.25, 1.5,
        2.0, 2.5, 3.0, 4.0, 6.0, 8.0)
SHAPES = [(1.0, b, c) for b in GRID for c in GRID]


def lattice_index(points: np.ndarray) -> np.ndarray:
    return points[..., 0] * 9 + points[..., 1] * 3 + points[..., 2]


def base_templates() -> np.ndarray:
    """The plain and cone templates (leaf side 2), without any table simplex."""
    return np.rint(luts.TEMPLATES[D][:luts.TABLE_FIRST_ID[D]] * 2).astype(np.int64)


def _quality(tets: np.ndarray, shape) -> dict:
    pts = (tets * np.asarray(shape)).reshape(-1, 3).astype(float)
    return quality_data(pts, np.arange(len(pts)).reshape(-1, 4))


def candidates() -> np.ndarray:
    """(n, 4) lattice indices of every tetrahedron within the bounds of the base templates
    under every cell shape of the grid."""
    combos = np.array(list(itertools.combinations(range(27), 4)))
    tets = LATTICE[combos]
    vol = np.linalg.det((tets[:, 1:] - tets[:, :1]).astype(float))
    keep = np.abs(vol) > 0.5
    combos, tets = combos[keep], tets[keep]
    base = base_templates()
    ok = np.ones(len(tets), dtype=bool)
    for shape in SHAPES:
        limit = _quality(base, shape)
        q = _quality(tets, shape)
        ok &= q["quality"] <= limit["quality"].max() + EPS
        ok &= q["min_dihedral"] >= limit["min_dihedral"].min() - EPS
        ok &= q["max_dihedral"] <= limit["max_dihedral"].max() + EPS
    return combos[ok]


def contains(cand: np.ndarray) -> np.ndarray:
    """(n, 27) bool: lattice points in each closed candidate, its corners excepted."""
    tets = LATTICE[cand].astype(float)
    edges = np.transpose(tets[:, 1:] - tets[:, :1], (0, 2, 1))
    lam = np.einsum("nij,npj->npi", np.linalg.inv(edges), LATTICE[None] - tets[:, :1])
    inside = (lam >= -EPS).all(-1) & (lam.sum(-1) <= 1 + EPS)
    inside[np.arange(len(cand))[:, None], cand] = False
    return inside


def boundary_triangles(config: np.ndarray, v: int) -> list[tuple[int, int, int]]:
    """Sorted lattice-index triples of the face table's triangles for this leaf."""
    tris = []
    for f, fsites in enumerate(luts.FACE_SITES[D]):
        case = sum(int(config[s]) << i for i, s in enumerate(fsites))
        for simplex in luts.FACE_LUT[D][v][f][case]:
            idx = [int(i) for i in lattice_index(simplex.astype(np.int64)) if i != CENTRE]
            tris.append(tuple(sorted(idx)))
    return tris


def on_leaf_face(tri) -> bool:
    p = LATTICE[list(tri)]
    return any((p[:, a] == s).all() for a in range(3) for s in (0, 2))


def solve(cand, inside, points: np.ndarray, btris, centre: bool, time_limit: float,
          stabiliser=()):
    """Fewest candidates tiling the leaf with these boundary triangles, or None; the
    tiling is kept by every symmetry in `stabiliser` (those that fix the leaf), so the
    table is one function of the leaf whatever symmetry maps a class to it."""
    present = np.zeros(27, dtype=bool)
    present[points] = True
    present[CENTRE] |= centre
    use = present[cand].all(axis=1) & ~(inside & present[None]).any(axis=1)
    cand = cand[use]
    bset = set(btris)
    rows, cols, vals, row_of = [], [], [], {}
    kept = []
    for t, c in enumerate(cand):
        facets = []
        for k in range(4):
            tri = tuple(sorted(int(x) for x in np.delete(c, k)))
            if on_leaf_face(tri) and tri not in bset:
                break
            p = LATTICE[list(tri)].astype(float)
            side = np.sign(np.linalg.det(np.stack([p[1] - p[0], p[2] - p[0],
                                                   LATTICE[c[k]] - p[0]])))
            facets.append((tri, 1.0 if tri in bset else side))
        else:
            for tri, value in facets:
                rows.append(row_of.setdefault(tri, len(row_of)))
                cols.append(len(kept))
                vals.append(value)
            kept.append(t)
    if any(tri not in row_of for tri in bset):
        return None
    kept = np.asarray(kept)
    # invariance: x_t = x_s(t) for every symmetry s of the leaf (0 when s(t) is no candidate)
    column = {tuple(sorted(c)): j for j, c in enumerate(cand[kept].tolist())}
    n_rows = len(row_of)
    for perm, flips in stabiliser:
        images = lattice_index(transform(LATTICE[cand[kept]], perm, flips))
        for j, image in enumerate(images.tolist()):
            k = column.get(tuple(sorted(image)))
            if k == j:
                continue
            rows.append(n_rows)
            cols.append(j)
            vals.append(1.0)
            if k is not None:
                rows.append(n_rows)
                cols.append(k)
                vals.append(-1.0)
            n_rows += 1
    a = coo_matrix((vals, (rows, cols)), shape=(n_rows, len(kept))).tocsr()
    rhs = np.zeros(n_rows)
    rhs[[row_of[tri] for tri in bset]] = 1.0
    tets = LATTICE[cand[kept]].astype(float)
    vol = np.abs(np.linalg.det(tets[:, 1:] - tets[:, :1]))
    res = milp(np.ones(len(kept)), integrality=np.ones(len(kept)), bounds=Bounds(0, 1),
               constraints=[LinearConstraint(a, rhs, rhs), LinearConstraint(vol[None], 48, 48)],
               options={"time_limit": time_limit})
    if res.x is None:
        return None
    return cand[kept[res.x > 0.5]], bool(res.status == 0)


def symmetries():
    """(perm, flips) of the cube [0, 2]^3; an odd number of flips swaps the parities."""
    return [(perm, flips) for perm in itertools.permutations(range(3))
            for flips in itertools.product((False, True), repeat=3)]


def transform(points: np.ndarray, perm, flips) -> np.ndarray:
    q = points[..., list(perm)].copy()
    q[..., list(flips)] = 2 - q[..., list(flips)]
    return q


def orient(tets_idx: np.ndarray) -> np.ndarray:
    """Reorder lattice-index tetrahedra to positive volume."""
    t = LATTICE[tets_idx]
    det = np.linalg.det((t[:, 1:] - t[:, :1]).astype(float))
    out = tets_idx.copy()
    neg = det < 0
    out[neg, 0], out[neg, 1] = tets_idx[neg, 1], tets_idx[neg, 0]
    return out


def verify(tets_idx: np.ndarray, btris, limits) -> None:
    """Raise unless the tetrahedra tile the leaf face to face with these boundary
    triangles, positively, within the quality limits."""
    t = LATTICE[tets_idx].astype(float)
    vol = np.linalg.det(t[:, 1:] - t[:, :1])
    assert (vol > 0).all() and abs(vol.sum() - 48) < 1e-9
    count: dict = {}
    for c in tets_idx:
        for k in range(4):
            tri = tuple(sorted(int(x) for x in np.delete(c, k)))
            count[tri] = count.get(tri, 0) + 1
    boundary = sorted(tri for tri, n in count.items() if n == 1)
    assert boundary == sorted(btris) and all(n in (1, 2) for n in count.values())
    q = _quality(LATTICE[tets_idx], (1.0, 1.0, 1.0))
    assert q["quality"].max() <= limits["quality"] + EPS
    assert q["min_dihedral"].min() >= limits["min_dihedral"] - EPS
    assert q["max_dihedral"].max() <= limits["max_dihedral"] + EPS


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time-limit", type=float, default=60.0,
                        help="seconds per MILP (the best tiling found by then is kept)")
    parser.add_argument("--out", type=Path, default=Path(luts.__file__).parent / "leaf_tables.npz")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    cand = candidates()
    inside = contains(cand)
    base = _quality(base_templates(), (1.0, 1.0, 1.0))
    limits = {"quality": base["quality"].max(), "min_dihedral": base["min_dihedral"].min(),
              "max_dihedral": base["max_dihedral"].max()}
    print(f"{len(cand)} candidate tetrahedra ({time.perf_counter() - t0:.1f} s)", flush=True)

    configs = leaf_configurations(D)
    weights = np.left_shift(np.int64(1), np.arange(configs.shape[1], dtype=np.int64))
    codes = configs.astype(np.int64) @ weights
    code_index = {int(c): i for i, c in enumerate(codes)}
    sites = luts.SITES[D].astype(np.int64)
    site_of = {tuple(s): i for i, s in enumerate(sites.tolist())}
    syms = symmetries()
    # image of every (configuration, variant) under every symmetry: (code, variant)
    images = []
    for perm, flips in syms:
        moved = np.zeros_like(configs)
        moved[:, [site_of[tuple(p)] for p in transform(sites, perm, flips).tolist()]] = configs
        images.append((moved.astype(np.int64) @ weights, sum(flips) % 2))

    entries = {}                      # (variant, code) -> (n, 4) lattice indices
    n_classes = n_optimal = 0
    solved: dict = {}
    for v in VARIANTS:
        for i, code in enumerate(codes.tolist()):
            if (v, code) in solved or code == 0:
                continue
            n_classes += 1
            btris = boundary_triangles(configs[i], v)
            points = np.unique(np.array(btris).ravel())
            # the symmetries that fix this leaf (an odd number of flips swaps the parity)
            stabiliser = [g for g, (moved, odd) in zip(syms, images)
                          if not odd and moved[i] == code]
            best, optimal = None, True
            for centre in (False, True):
                found = solve(cand, inside, points, btris, centre, args.time_limit,
                              stabiliser)
                if found is not None and (best is None or len(found[0]) < len(best)):
                    best, optimal = found
            # every image of this (configuration, variant): the same count, mapped
            for (perm, flips), (moved, odd) in zip(syms, images):
                w = v if not odd else 3 - v
                key = (w, int(moved[i]))
                if key in solved:
                    continue
                solved[key] = True
                if best is None or len(best) >= len(btris):
                    continue
                mapped = lattice_index(transform(LATTICE[best], perm, flips))
                mapped = orient(mapped)
                verify(mapped, boundary_triangles(configs[code_index[key[1]]], w), limits)
                entries[key] = mapped
            n_optimal += optimal
            if n_classes % 20 == 0:
                print(f"{n_classes} classes, {len(entries)} entries, "
                      f"{time.perf_counter() - t0:.0f} s", flush=True)
    keys = sorted(entries)
    simplices = np.unique(np.concatenate([np.sort(entries[k], axis=1) for k in keys]), axis=0)
    # distinct simplices (sorted corners) -> positively oriented table rows
    simplices = orient(simplices)
    sid = {tuple(sorted(s)): j for j, s in enumerate(simplices.tolist())}
    offset = np.zeros(len(keys) + 1, dtype=np.int32)
    member = []
    for j, k in enumerate(keys):
        member.extend(sid[tuple(sorted(s))] for s in entries[k].tolist())
        offset[j + 1] = len(member)
    key_arr = np.array([(w << 18) | c for w, c in keys], dtype=np.int32)
    member = np.array(member, dtype=np.int16)
    simplex = LATTICE[simplices].astype(np.int8)
    new_entry, new_point = luts.table_new_points(key_arr, offset, member, simplex)
    np.savez_compressed(args.out, key=key_arr, offset=offset, member=member, simplex=simplex,
                        new_entry=new_entry.astype(np.int32), new_point=new_point)
    print(f"{n_classes} classes ({n_optimal} proven optimal), {len(keys)} entries, "
          f"{len(simplices)} distinct tetrahedra -> {args.out} "
          f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
