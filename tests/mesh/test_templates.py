"""Look-up tables: conforming by construction, filling every leaf, and the proven bounds."""

import math

import numpy as np
import pytest

from napari_swa_imesh.mesh.mesher import _templates_luts as luts
from napari_swa_imesh.mesh.model._bounds import (
    format_quality_table,
    leaf_configurations,
    quality_bounds,
    quality_table,
)
from napari_swa_imesh.mesh.model._quality import QUALITY_METRICS, signed_volumes


def _facets_on(simplices: np.ndarray, axis: int, side: int) -> set:
    """Facets (as sorted coordinate tuples) of `simplices` lying on the plane axis = side."""
    out = set()
    for s in simplices:
        on = [tuple(p) for p in s.tolist() if p[axis] == side]
        if len(on) == s.shape[1]:
            out.add(tuple(sorted(on)))
    return out


def _valid_cases(d, f, v=0):
    return [c for c in range(1 << len(luts.FACE_SITES[d][f])) if len(luts.FACE_LUT[d][v][f][c])]


def _variants():
    return [(d, v) for d in (2, 3) for v in luts.VARIANTS[d]]


def _across(v):
    """The variant of the same-size neighbour across a face: parity flips, lowest stays."""
    return v if v == 0 else 3 - v


def _child_variant(v, corner):
    """Variant of the child at `corner` (in {0,1}^d) of a leaf of variant `v`."""
    return v if v == 0 else 1 + sum(corner) % 2


@pytest.mark.parametrize("d", [2, 3])
def test_plain_leaves_fill_the_cube_positively(d):
    assert np.array_equal(luts.KUHN[d], luts.PLAIN[d][0])
    for v in luts.VARIANTS[d]:
        plain = luts.PLAIN[d][v].astype(float)
        pts = plain.reshape(-1, d)
        vol = signed_volumes(pts, np.arange(len(pts)).reshape(-1, d + 1))
        assert (vol > 0).all() and vol.sum() == pytest.approx(1.0)
        assert len(plain) == (math.factorial(d) if v == 0 else 5)


@pytest.mark.parametrize(("d", "v"), _variants())
def test_shared_faces_are_cut_the_same_from_both_sides(d, v):
    w = _across(v)
    for f, (axis, side) in enumerate(luts.FACES[d]):
        if side == 2:
            continue
        g = luts.FACES[d].index((axis, 2))
        shift = np.zeros(d, int)
        shift[axis] = 2
        for case in _valid_cases(d, f, v):
            # the face's sites, in the same bit order seen from the neighbour below
            mine = {tuple(luts.SITES[d][s])
                    for i, s in enumerate(luts.FACE_SITES[d][f]) if case >> i & 1}
            theirs = 0
            for i, s in enumerate(luts.FACE_SITES[d][g]):
                if tuple(luts.SITES[d][s] - shift) in mine:
                    theirs |= 1 << i
            a = _facets_on(luts.FACE_LUT[d][v][f][case], axis, 0)
            b = _facets_on(luts.FACE_LUT[d][w][g][theirs] - shift, axis, 0)
            assert a == b and a, (f, case)


@pytest.mark.parametrize(("d", "v"), _variants())
def test_plain_faces_match_plain_leaves_and_quadrants_match_children(d, v):
    plain_leaf = luts.PLAIN[d][v] * 2
    for f, (axis, side) in enumerate(luts.FACES[d]):
        plain = _facets_on(luts.FACE_LUT[d][v][f][0], axis, side)
        assert plain == _facets_on(plain_leaf, axis, side)
        # and the plain leaf across the face (other parity) cuts it alike
        shift = np.zeros(d, int)
        shift[axis] = 2 if side == 2 else -2
        across = luts.PLAIN[d][_across(v)] * 2 + shift
        assert plain == _facets_on(across, axis, side)
        full = (1 << len(luts.FACE_SITES[d][f])) - 1
        # a face whose centre is a vertex is cut like the faces of four plain children
        children = set()
        for corner in np.ndindex((2,) * d):
            child = luts.PLAIN[d][_child_variant(v, corner)] + np.array(corner)
            children |= _facets_on(child, axis, side)
        if d == 3:
            assert _facets_on(luts.FACE_LUT[d][v][f][full], axis, side) == children


def test_parity_rule_is_the_even_corner_diagonal():
    # a plain face of an even leaf is cut through its corners with sum(c / side) even;
    # quadrants of a face with its centre present: an X through the centre
    for f, (axis, side) in enumerate(luts.FACES[3]):
        for v in (1, 2):
            for tri in _facets_on(luts.FACE_LUT[3][v][f][0], axis, side):
                others = _facets_on(luts.FACE_LUT[3][v][f][0], axis, side) - {tri}
                shared = set(tri) & set(next(iter(others)))
                assert all((sum(c) // 2 + v - 1) % 2 == 0 for c in shared), (f, v)
            full = (1 << len(luts.FACE_SITES[3][f])) - 1
            for tri in _facets_on(luts.FACE_LUT[3][v][f][full], axis, side):
                assert (1, 1) in {tuple(c[a] for a in range(3) if a != axis) for c in tri}


@pytest.mark.parametrize(("d", "v"), _variants())
def test_every_face_case_covers_its_face(d, v):
    for f in range(len(luts.FACES[d])):
        for case in _valid_cases(d, f, v):
            simplices = luts.FACE_LUT[d][v][f][case].astype(float)
            pts = simplices.reshape(-1, d)
            vol = signed_volumes(pts, np.arange(len(pts)).reshape(-1, d + 1))
            # cone of height 1 over a face of area 2^(d-1): volume 2^(d-1) / d
            assert (vol > 0).all() and vol.sum() == pytest.approx(2 ** (d - 1) / d)


def test_configuration_counts():
    assert leaf_configurations(2).shape == (16, 4)
    configs = leaf_configurations(3)
    assert configs.shape[1] == 18
    # a face centre only with all four of its edge midpoints
    assert len(configs) == len({tuple(c) for c in configs.tolist()})
    rows = quality_table(2)
    assert rows[0]["n_configurations_up_to_symmetry"] == 6  # the reference's six (Table 3.3)


def test_quality_table_2d_bound():
    rows = quality_table(2)
    assert max(r["radius_edge_ratio"] for r in rows) == pytest.approx(1 / math.sqrt(2))
    assert min(r["min_angle"] for r in rows) == pytest.approx(45)
    assert max(r["max_angle"] for r in rows) == pytest.approx(90)
    assert "bound: radius-to-edge ratio <= 0.7071" in format_quality_table(rows)


def test_quality_table_3d_bound():
    rows = quality_table(3)
    worst = max(r["radius_edge_ratio"] for r in rows)
    assert worst == pytest.approx(math.sqrt(5) / 2)
    assert worst < math.sqrt(29) / 4
    assert min(r["min_dihedral"] for r in rows) == pytest.approx(
        math.degrees(math.atan(1 / math.sqrt(2))))
    # 90 + arctan(1/sqrt(2)): the fan simplex over a face corner
    assert max(r["max_dihedral"] for r in rows) == pytest.approx(
        90 + math.degrees(math.atan(1 / math.sqrt(2))))
    text = format_quality_table(rows)
    assert "dihedral angles in [35.264, 125.264] deg" in text
    assert len(text.splitlines()) == len(rows) + 4


@pytest.mark.parametrize("d", [2, 3])
def test_quality_bounds_are_what_the_table_proves(d):
    # the GUI shades these ranges: the bound end is the table's worst value, the other
    # end the regular simplex, and every template simplex lies inside
    rows = quality_table(d)
    bounds = quality_bounds(d)
    angles = ("min_angle", "max_angle") if d == 2 else ("min_dihedral", "max_dihedral")
    assert set(bounds) == {"quality", *angles}
    ratios = [r["radius_edge_ratio"] for r in rows]
    assert bounds["quality"][1] == pytest.approx(max(ratios))
    assert bounds[angles[0]][0] == pytest.approx(min(r[angles[0]] for r in rows))
    assert bounds[angles[1]][1] == pytest.approx(max(r[angles[1]] for r in rows))
    for name, (lo, hi) in bounds.items():
        column = "radius_edge_ratio" if name == "quality" else name
        assert all(lo - 1e-9 <= r[column] <= hi + 1e-9 for r in rows), name
        metric = next(m for m in QUALITY_METRICS if m.name == name and m.dim == d)
        assert metric.optimal_range == pytest.approx((lo, hi)), name


def test_2d_bounds_are_the_proven_ones_not_the_papers():
    bounds = quality_bounds(2)
    assert bounds["quality"][1] == pytest.approx(1 / math.sqrt(2))  # not sqrt(5)/2
    assert bounds["min_angle"] == pytest.approx((45.0, 60.0))  # not 26.6 deg
    assert bounds["max_angle"] == pytest.approx((60.0, 90.0))


def test_bad_dim():
    with pytest.raises(ValueError, match="dim 2 or 3"):
        quality_table(4)
    with pytest.raises(ValueError, match="dim 2 or 3"):
        quality_bounds(1)
