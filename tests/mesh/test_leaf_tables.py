"""The sited-leaf table (``mesh/mesher/leaf_tables.npz``), checked entry by entry on its own.

The table is made offline by ``tools/leaf_tables.py``; nothing here reuses that script.
Every entry must tile its leaf face to face with positive tetrahedra whose boundary is
exactly the face look-up table's triangles for that configuration (so neighbours agree
as they do with cones), each tetrahedron within the proven bounds, and fewer of them
than the cones.
"""

import importlib.resources
import itertools
import math

import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels, quality_bounds
from napari_swa_imesh.mesh.checks._checks import check_mesh
from napari_swa_imesh.mesh.mesher import _templates_luts as luts
from napari_swa_imesh.mesh.mesher._lattice import aspect_table
from napari_swa_imesh.mesh.model._bounds import leaf_configurations
from napari_swa_imesh.mesh.model._quality import quality_data, signed_volumes

TABLE = luts.LEAF_TABLE[3]
CENTRE = (1, 1, 1)


def _all_entries():
    """(variant, code) per entry, and every tetrahedron (N, 4, 3) with its entry (N,)."""
    variant, code = TABLE.key >> 18, TABLE.key & ((1 << 18) - 1)
    entry = np.repeat(np.arange(len(TABLE.key)), np.diff(TABLE.offset))
    return variant, code, TABLE.simplex[TABLE.member].astype(np.int64), entry


def _facet_keys(entry, corners):
    """One int64 per (entry, unordered triangle of lattice points)."""
    idx = np.sort(corners @ np.array([9, 3, 1]), axis=-1)
    return ((entry * 27 + idx[..., 0]) * 27 + idx[..., 1]) * 27 + idx[..., 2]


def _face_triangles(v, code):
    """(t, 3, 3) the face look-up table's triangles of a leaf (the cones less their apex)."""
    tris = []
    for f, fsites in enumerate(luts.FACE_SITES[3]):
        case = sum((code >> s & 1) << i for i, s in enumerate(fsites))
        for cone in luts.FACE_LUT[3][v][f][case].tolist():
            tris.append([p for p in cone if tuple(p) != CENTRE])
    return np.array(tris, dtype=np.int64)


def test_the_table_ships_with_the_package():
    assert (importlib.resources.files("napari_swa_imesh.mesh.mesher") / "leaf_tables.npz").is_file()
    assert len(TABLE.key) > 1000 and (np.diff(TABLE.key) > 0).all()


def test_every_entry_tiles_its_leaf_with_the_face_tables_triangles():
    valid = set((leaf_configurations(3).astype(np.int64)
                 @ (1 << np.arange(18, dtype=np.int64))).tolist())
    variant, code, tets, entry = _all_entries()
    assert set(variant.tolist()) <= {1, 2} and set(code.tolist()) <= valid and 0 not in code
    # positive tetrahedra filling each leaf (side 2, so 6 x volume 8 = 48)
    det = np.linalg.det((tets[:, 1:] - tets[:, :1]).astype(float))
    assert (det > 0).all()
    np.testing.assert_allclose(np.bincount(entry, weights=det), 48.0)
    # facets: seen once on the leaf's boundary, twice inside, from opposite sides
    keys, sides = [], []
    for k in range(4):
        facet = np.delete(tets, k, axis=1)
        keys.append(_facet_keys(entry, facet))
        order = np.argsort(facet @ np.array([9, 3, 1]), axis=1)
        a, b, c = (np.take_along_axis(facet, order[:, j, None, None], axis=1)[:, 0]
                   for j in range(3))
        sides.append(np.sign(np.einsum("ij,ij->i", np.cross(b - a, c - a), tets[:, k] - a)))
    keys, sides = np.concatenate(keys), np.concatenate(sides)
    unique, inverse, count = np.unique(keys, return_inverse=True, return_counts=True)
    assert set(count.tolist()) <= {1, 2}
    assert (np.bincount(inverse, weights=sides)[count == 2] == 0).all()
    # the boundary facets of each entry are the face table's triangles, and only they
    expected, n_cones = [], np.zeros(len(TABLE.key), np.int64)
    for e, (v, c) in enumerate(zip(variant.tolist(), code.tolist())):
        tris = _face_triangles(v, c)
        expected.append(_facet_keys(np.full(len(tris), e), tris))
        n_cones[e] = len(tris)
    np.testing.assert_array_equal(unique[count == 1], np.sort(np.concatenate(expected)))
    # stored only where it saves tetrahedra
    assert (np.diff(TABLE.offset) < n_cones).all()
    # the new points the mesher marks: every point used, less corners and sites present
    point = tets @ np.array([9, 3, 1])                              # (N, 4) lattice index
    used = np.unique(np.repeat(entry, 4) * 27 + point.ravel())
    e, p = used // 27, used % 27
    lattice = np.array(list(itertools.product((0, 1, 2), repeat=3)))
    corner = (lattice[p] != 1).all(axis=1)
    site_bit = {tuple(s): i for i, s in enumerate(luts.SITES[3].tolist())}
    bit = np.array([site_bit.get(tuple(q), -1) for q in lattice.tolist()])[p]
    present = (bit >= 0) & ((code[e] >> np.maximum(bit, 0)) & 1).astype(bool)
    expected_new = np.sort(used[~corner & ~present])
    stored = np.sort(TABLE.new_entry * 27 + TABLE.new_point.astype(np.int64) @ np.array([9, 3, 1]))
    np.testing.assert_array_equal(stored, expected_new)


def test_every_table_tetrahedron_is_within_the_proven_bounds():
    tets = TABLE.simplex.astype(float)
    q = quality_data(tets.reshape(-1, 3), np.arange(4 * len(tets)).reshape(-1, 4))
    # the published numbers, not quality_bounds (built from these same templates)
    low = math.degrees(math.atan(1 / math.sqrt(2)))          # 35.264
    assert q["quality"].max() <= math.sqrt(5) / 2 + 1e-12
    assert q["min_dihedral"].min() >= low - 1e-9
    assert q["max_dihedral"].max() <= 90 + low + 1e-9       # 125.264
    bounds = quality_bounds(3)
    assert bounds["quality"][1] == pytest.approx(math.sqrt(5) / 2)
    assert bounds["min_dihedral"][0] == pytest.approx(low)


def test_the_table_leaves_every_aspect_and_stretch_bound_as_it_was():
    base = luts.TEMPLATES[3][:luts.TABLE_FIRST_ID[3]]
    table = luts.TEMPLATES[3][luts.TABLE_FIRST_ID[3]:]
    assert len(table) == len(TABLE.simplex)
    grid = (0.25, 0.5, 0.8, 1.0, 1.2, 1.5, 2.0, 3.0, 5.0)
    for shape in [(1.0, b, c) for b, c in itertools.product(grid, grid)]:
        def metrics(t, shape=shape):
            pts = (t * np.asarray(shape)).reshape(-1, 3)
            return quality_data(pts, np.arange(len(pts)).reshape(-1, 4))
        old, new = metrics(base), metrics(table)
        assert new["quality"].max() <= old["quality"].max() + 1e-9, shape
        assert new["min_dihedral"].min() >= old["min_dihedral"].min() - 1e-9, shape
        assert new["max_dihedral"].max() <= old["max_dihedral"].max() + 1e-9, shape
    # the published rows (README, `swa-imesh bounds`)
    rows = {r["aspect"]: r for r in aspect_table(3, (1.0, 1.2, 1.5))}
    assert rows[1.2]["worst_ratio"] == pytest.approx(1.318484, abs=1e-6)
    assert rows[1.2]["min_angle"] == pytest.approx(30.508959, abs=1e-6)
    assert rows[1.5]["worst_ratio"] == pytest.approx(1.700184, abs=1e-6)


def test_meshes_use_the_table_and_save_tetrahedra(monkeypatch):
    rng = np.random.default_rng(7)
    lab = np.ones((24, 24, 24), np.uint8)
    lab[rng.random(lab.shape) < 0.01] = 2
    with_table = mesh_labels(lab)
    monkeypatch.setitem(luts.LEAF_TABLE, 3, luts.LeafTable(
        np.zeros(0, np.int32), np.zeros(1, np.int64), TABLE.member, TABLE.simplex,
        np.zeros(0, np.int64), np.zeros((0, 3), np.int8)))
    cones = mesh_labels(lab)
    assert with_table.n_cells < cones.n_cells
    assert with_table.info["n_leaves_meshed"] == cones.info["n_leaves_meshed"]
    vol = signed_volumes(with_table.points, with_table.cells)
    assert (vol > 0).all() and vol.sum() == pytest.approx(lab.size)
    assert check_mesh(with_table, lab).all_passed


def test_the_table_commutes_with_the_cubes_symmetries():
    # a leaf rotated or reflected gets the rotated or reflected tetrahedra (an odd number
    # of reflections swaps the two parities), so a transposed image gets the transposed
    # mesh as it does with the plain and cone templates
    variant, code, tets, entry = _all_entries()
    key = TABLE.key.astype(np.int64)

    def tet_keys(entry_key, t):
        idx = np.sort(t @ np.array([9, 3, 1]), axis=1)
        return ((((entry_key * 27 + idx[:, 0]) * 27 + idx[:, 1]) * 27 + idx[:, 2]) * 27
                + idx[:, 3])

    expected = np.sort(tet_keys(key[entry], tets))
    sites = luts.SITES[3].astype(np.int64)
    site_of = {tuple(s): i for i, s in enumerate(sites.tolist())}
    for perm in itertools.permutations(range(3)):
        for flips in itertools.product((False, True), repeat=3):
            def move(points, perm=perm, flips=flips):
                q = points[..., list(perm)].copy()
                q[..., list(flips)] = 2 - q[..., list(flips)]
                return q
            image = np.array([site_of[tuple(p)] for p in move(sites).tolist()])
            moved_code = np.zeros_like(code)
            for i, j in enumerate(image):
                moved_code |= ((code >> i) & 1) << j
            moved_variant = 3 - variant if sum(flips) % 2 else variant
            moved_key = (moved_variant.astype(np.int64) << 18) | moved_code
            got = np.sort(tet_keys(moved_key[entry], move(tets)))
            np.testing.assert_array_equal(got, expected, err_msg=f"{perm} {flips}")
