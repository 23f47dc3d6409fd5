"""Quality metrics against hand-made simplices and brute-force formulas."""

import math

import numpy as np
import pytest

from napari_swa_imesh.mesh.model._quality import (
    QUALITY_METRICS,
    dihedral_angles,
    max_angle,
    min_angle,
    radius_edge_ratio,
    signed_volumes,
    triangle_angles,
)

EQUILATERAL = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(3) / 2]])
REGULAR_TET = np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])


def _brute_ratio(p):
    """Circumradius by solving the linear system, over the shortest edge."""
    a = 2 * (p[1:] - p[0])
    b = (p[1:] ** 2).sum(1) - (p[0] ** 2).sum()
    centre = np.linalg.solve(a, b)
    radius = np.linalg.norm(centre - p[0])
    edges = [np.linalg.norm(p[i] - p[j]) for i in range(len(p)) for j in range(i + 1, len(p))]
    return radius / min(edges)


def test_equilateral_and_right_triangles():
    cells = [[0, 1, 2]]
    assert radius_edge_ratio(EQUILATERAL, cells)[0] == pytest.approx(1 / math.sqrt(3))
    assert min_angle(EQUILATERAL, cells)[0] == pytest.approx(60)
    right = np.array([[0.0, 0], [1, 0], [0, 1]])
    assert radius_edge_ratio(right, cells)[0] == pytest.approx(1 / math.sqrt(2))
    lo, hi = triangle_angles(right, cells)
    assert (lo[0], hi[0]) == (pytest.approx(45), pytest.approx(90))
    # the reference's worst 2-D template: half of a 1 x 2 rectangle
    half = np.array([[0.0, 0], [2, 0], [0, 1]])
    assert min_angle(half, cells)[0] == pytest.approx(math.degrees(math.atan(0.5)))
    assert radius_edge_ratio(half, cells)[0] == pytest.approx(math.sqrt(5) / 2)
    assert max_angle(half, cells)[0] == pytest.approx(90)


def test_regular_and_corner_tetrahedra():
    cells = [[0, 1, 2, 3]]
    assert radius_edge_ratio(REGULAR_TET, cells)[0] == pytest.approx(math.sqrt(6) / 4)
    lo, hi = dihedral_angles(REGULAR_TET, cells)
    assert lo[0] == pytest.approx(math.degrees(math.acos(1 / 3)))
    assert hi[0] == pytest.approx(math.degrees(math.acos(1 / 3)))
    corner = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    lo, hi = dihedral_angles(corner, cells)
    assert lo[0] == pytest.approx(math.degrees(math.acos(1 / math.sqrt(3))))
    assert hi[0] == pytest.approx(90)
    kuhn = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]])
    assert radius_edge_ratio(kuhn, cells)[0] == pytest.approx(math.sqrt(3) / 2)


@pytest.mark.parametrize("d", [2, 3])
def test_random_simplices_match_brute_force(d):
    rng = np.random.default_rng(d)
    points = rng.normal(size=(200, d))
    cells = np.array([rng.choice(200, d + 1, replace=False) for _ in range(300)])
    ratio = radius_edge_ratio(points, cells)
    np.testing.assert_allclose(ratio, [_brute_ratio(points[c]) for c in cells], rtol=1e-8)
    vol = signed_volumes(points, cells)
    brute = [np.linalg.det(points[c[1:]] - points[c[0]]) / math.factorial(d) for c in cells]
    np.testing.assert_allclose(vol, brute, rtol=1e-10, atol=1e-14)
    # swapping two vertices flips the sign and keeps the metrics
    flipped = cells[:, [1, 0] + list(range(2, d + 1))]
    np.testing.assert_allclose(signed_volumes(points, flipped), -vol)
    np.testing.assert_allclose(radius_edge_ratio(points, flipped), ratio)
    if d == 2:
        lo, hi = triangle_angles(points, cells)
        for c, a, b in zip(cells[:20], lo, hi):
            p = points[c]
            ang = []
            for k in range(3):
                u, v = p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]
                ang.append(math.degrees(math.acos(u @ v / np.linalg.norm(u) / np.linalg.norm(v))))
            assert sum(ang) == pytest.approx(180)
            assert (a, b) == (pytest.approx(min(ang)), pytest.approx(max(ang)))


def _brute_dihedral(p):
    """Dihedral angle at each edge from the other two vertices projected off the edge."""
    out = []
    for i in range(4):
        for j in range(i + 1, 4):
            k, q = [m for m in range(4) if m not in (i, j)]
            e = (p[j] - p[i]) / np.linalg.norm(p[j] - p[i])
            u = p[k] - p[i] - (p[k] - p[i]) @ e * e
            v = p[q] - p[i] - (p[q] - p[i]) @ e * e
            out.append(math.degrees(math.acos(u @ v / np.linalg.norm(u) / np.linalg.norm(v))))
    return min(out), max(out)


def test_dihedral_angles_match_brute_force():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(4 * 50, 3))
    cells = np.arange(len(points)).reshape(-1, 4)
    lo, hi = dihedral_angles(points, cells)
    brute = np.array([_brute_dihedral(points[c]) for c in cells])
    np.testing.assert_allclose(lo, brute[:, 0], rtol=1e-8)
    np.testing.assert_allclose(hi, brute[:, 1], rtol=1e-8)


def test_degenerate_cells_are_flagged_not_raised():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    cells = [[0, 1, 2, 3]]
    assert radius_edge_ratio(points, cells)[0] == math.inf
    assert signed_volumes(points, cells)[0] == 0
    assert radius_edge_ratio(points[:, :2], [[0, 1, 2]])[0] == math.inf


def test_metric_table_covers_cell_data():
    names = {(m.name, m.dim) for m in QUALITY_METRICS}
    assert {("quality", 2), ("quality", 3), ("min_angle", 2), ("min_dihedral", 3),
            ("max_dihedral", 3)} <= names
    for m in QUALITY_METRICS:
        assert m.valid_range[0] <= m.optimal_range[0] <= m.optimal_range[1] <= m.valid_range[1]


def test_wrong_cell_kind():
    with pytest.raises(ValueError, match="need triangles"):
        min_angle(REGULAR_TET, [[0, 1, 2, 3]])
    with pytest.raises(ValueError, match="needs tetrahedra"):
        dihedral_angles(EQUILATERAL, [[0, 1, 2]])
