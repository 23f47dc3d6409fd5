"""Element quality metrics: pure functions of ``(points, cells)``, one value per cell.

Every function takes ``points (N, d) float`` and ``cells (M, d+1) int`` (triangles in 2-D,
tetrahedra in 3-D) and works in chunks, so memory stays bounded on meshes of tens of
millions of elements. Degenerate (zero-volume) cells give ``inf`` ratios and ``nan``
angles instead of raising.

``QUALITY_METRICS`` describes each metric (units, valid range, optimal range) so a GUI can
shade a histogram without knowing the formulas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["QUALITY_METRICS", "QualityMetric", "dihedral_angles", "max_angle", "min_angle",
           "quality_data", "radius_edge_ratio", "signed_volumes", "triangle_angles"]

_CHUNK = 1 << 20


@dataclass(frozen=True)
class QualityMetric:
    """Description of one per-element metric.

    ``valid_range`` is what the metric can take on non-degenerate elements of dimension
    `dim`; ``optimal_range`` runs from the regular simplex's value to the bound the
    template mesher proves (isotropic spacing): every template element lies in it.
    ``mesh.model._bounds.quality_bounds`` derives the same ranges from the quality table, and
    a test holds the two equal.
    """

    name: str
    dim: int
    units: str
    valid_range: tuple[float, float]
    optimal_range: tuple[float, float]
    description: str


_REGULAR_DIHEDRAL = math.degrees(math.acos(1 / 3))  # 70.53 deg
# the proven template bounds (``swa-imesh bounds --dim d``): 2-D right isosceles
# triangles only; 3-D worst ratio sqrt(5)/2, dihedral angles atan(1/sqrt 2) = 35.26 deg
# to 90 + 35.26 deg
_WORST_DIHEDRAL = math.degrees(math.atan(1 / math.sqrt(2)))

QUALITY_METRICS: tuple[QualityMetric, ...] = (
    QualityMetric("quality", 2, "1", (1 / math.sqrt(3), math.inf),
                  (1 / math.sqrt(3), 1 / math.sqrt(2)),
                  "radius-to-edge ratio: circumradius / shortest edge (equilateral: 0.577)"),
    QualityMetric("quality", 3, "1", (math.sqrt(6) / 4, math.inf),
                  (math.sqrt(6) / 4, math.sqrt(5) / 2),
                  "radius-to-edge ratio: circumradius / shortest edge (regular: 0.612)"),
    QualityMetric("min_angle", 2, "deg", (0.0, 60.0), (45.0, 60.0),
                  "smallest interior angle of the triangle"),
    QualityMetric("max_angle", 2, "deg", (60.0, 180.0), (60.0, 90.0),
                  "largest interior angle of the triangle"),
    QualityMetric("min_dihedral", 3, "deg", (0.0, _REGULAR_DIHEDRAL),
                  (_WORST_DIHEDRAL, _REGULAR_DIHEDRAL),
                  "smallest dihedral angle of the tetrahedron (regular: 70.53)"),
    QualityMetric("max_dihedral", 3, "deg", (_REGULAR_DIHEDRAL, 180.0),
                  (_REGULAR_DIHEDRAL, 90.0 + _WORST_DIHEDRAL),
                  "largest dihedral angle of the tetrahedron (regular: 70.53)"),
)


def _chunks(points, cells):
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells)
    for start in range(0, len(cells), _CHUNK):
        yield start, points[cells[start:start + _CHUNK]]  # (m, d+1, d)


def _det(vectors: np.ndarray) -> np.ndarray:
    """(m, d, d) -> (m,) determinants, closed form for d = 2, 3."""
    if vectors.shape[-1] == 2:
        return vectors[:, 0, 0] * vectors[:, 1, 1] - vectors[:, 0, 1] * vectors[:, 1, 0]
    if vectors.shape[-1] == 3:
        return np.einsum("mi,mi->m", vectors[:, 0], np.cross(vectors[:, 1], vectors[:, 2]))
    return np.linalg.det(vectors)


def _corner_det(p: list) -> np.ndarray:
    """det(p1-p0, ..., pd-p0) from per-corner, per-axis arrays ``p[k][a]`` (d = 2, 3).

    The closed form on flat arrays: gathering coordinates axis by axis keeps chunks of
    elements in cache (callers at volume size use it instead of ``signed_volumes``).
    """
    return _edge_det([[p[k][a] - p[0][a] for a in range(len(p[0]))] for k in range(1, len(p))])


def _edge_det(e: list) -> np.ndarray:
    """Det of the edge vectors ``e[k][a]`` (d = 2, 3), the closed form in their dtype."""
    if len(e) == 2:
        return e[0][0] * e[1][1] - e[0][1] * e[1][0]
    return (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1])
            + e[0][1] * (e[1][2] * e[2][0] - e[1][0] * e[2][2])
            + e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]))


def signed_volumes(points, cells) -> np.ndarray:
    """Signed area (2-D) or volume (3-D) of each cell.

    Parameters
    ----------
    points : (N, d) array_like of float
    cells : (M, d+1) array_like of int

    Returns
    -------
    (M,) ndarray of float64
        ``det(p1-p0, ..., pd-p0) / d!``; positive for the mesh's orientation convention.

    Examples
    --------
    >>> signed_volumes([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]])
    array([0.5])
    """
    cells = np.asarray(cells)
    out = np.empty(len(cells))
    d = cells.shape[1] - 1
    for start, p in _chunks(points, cells):
        out[start:start + len(p)] = _det(p[:, 1:] - p[:, :1]) / math.factorial(d)
    return out


def radius_edge_ratio(points, cells) -> np.ndarray:
    """Circumradius divided by shortest edge, per triangle or tetrahedron.

    Parameters
    ----------
    points : (N, d) array_like of float, d = 2 or 3
    cells : (M, d+1) array_like of int

    Returns
    -------
    (M,) ndarray of float64
        1/sqrt(3) = 0.577 for an equilateral triangle, sqrt(6)/4 = 0.612 for a regular
        tetrahedron; ``inf`` for a degenerate cell.

    Examples
    --------
    >>> float(radius_edge_ratio([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]])[0])  # 0.7071...
    0.7071067811865476
    """
    cells = np.asarray(cells)
    out = np.empty(len(cells))
    d = cells.shape[1] - 1
    for start, p in _chunks(points, cells):
        e = p[:, 1:] - p[:, :1]  # (m, d, d) edges from vertex 0
        sq = np.einsum("mij,mij->mi", e, e)  # (m, d) squared lengths
        det = _det(e)
        with np.errstate(divide="ignore", invalid="ignore"):
            if d == 2:
                # circumcentre offset from p0 = perp(|a|^2 b - |b|^2 a) / (2 det)
                num = sq[:, 0, None] * e[:, 1] - sq[:, 1, None] * e[:, 0]
                radius = np.sqrt(np.einsum("mi,mi->m", num, num)) / (2 * np.abs(det))
            elif d == 3:
                a, b, c = e[:, 0], e[:, 1], e[:, 2]
                num = (sq[:, 0, None] * np.cross(b, c) + sq[:, 1, None] * np.cross(c, a)
                       + sq[:, 2, None] * np.cross(a, b))
                radius = np.sqrt(np.einsum("mi,mi->m", num, num)) / (2 * np.abs(det))
            else:
                raise ValueError("cells must be triangles or tetrahedra; "
                                 f"got {d + 1} vertices per cell.")
            i, j = np.triu_indices(d + 1, 1)
            ev = p[:, j] - p[:, i]  # (m, n_edges, d)
            shortest = np.sqrt(np.einsum("mki,mki->mk", ev, ev).min(axis=1))
            ratio = radius / shortest
        ratio[~np.isfinite(ratio) | (det == 0)] = np.inf
        out[start:start + len(p)] = ratio
    return out


def triangle_angles(points, cells) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest interior angle of each triangle, in degrees.

    Parameters
    ----------
    points : (N, 2) array_like of float
    cells : (M, 3) array_like of int

    Returns
    -------
    min_angle, max_angle : (M,) ndarray of float64
        Both 60 for an equilateral triangle; ``nan`` where an edge has zero length.
    """
    cells = np.asarray(cells)
    if cells.ndim != 2 or cells.shape[1] != 3:
        raise ValueError("angles need triangles (3 vertices per cell); "
                         f"got cells of shape {cells.shape}.")
    lo = np.empty(len(cells))
    hi = np.empty(len(cells))
    for start, p in _chunks(points, cells):
        angles = []
        for k in range(3):
            u = p[:, (k + 1) % 3] - p[:, k]
            v = p[:, (k + 2) % 3] - p[:, k]
            with np.errstate(divide="ignore", invalid="ignore"):
                cos = np.einsum("mi,mi->m", u, v) / np.sqrt(
                    np.einsum("mi,mi->m", u, u) * np.einsum("mi,mi->m", v, v))
            angles.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
        stacked = np.stack(angles, axis=1)
        lo[start:start + len(p)] = stacked.min(axis=1)
        hi[start:start + len(p)] = stacked.max(axis=1)
    return lo, hi


def min_angle(points, cells) -> np.ndarray:
    """Smallest interior angle of each triangle, in degrees.

    Parameters
    ----------
    points : (N, 2) array_like of float
    cells : (M, 3) array_like of int

    Returns
    -------
    (M,) ndarray of float64
        60 for an equilateral triangle; ``nan`` where an edge has zero length.

    Examples
    --------
    >>> min_angle([[0, 0], [2, 0], [0, 1]], [[0, 1, 2]]).round(3)
    array([26.565])
    """
    return triangle_angles(points, cells)[0]


def max_angle(points, cells) -> np.ndarray:
    """Largest interior angle of each triangle, in degrees: the other end of :func:`min_angle`.

    Takes the same ``points (N, 2)`` and ``cells (M, 3)``; returns ``(M,)`` float64, 60
    for an equilateral triangle, 90 for a right one, ``nan`` where an edge has zero length.

    Examples
    --------
    >>> max_angle([[0, 0], [2, 0], [0, 1]], [[0, 1, 2]]).round(3)
    array([90.])
    """
    return triangle_angles(points, cells)[1]


def dihedral_angles(points, cells) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest of the six dihedral angles of each tetrahedron, in degrees.

    Parameters
    ----------
    points : (N, 3) array_like of float
    cells : (M, 4) array_like of int

    Returns
    -------
    min_dihedral, max_dihedral : (M,) ndarray of float64
        Both 70.53 (arccos 1/3) for a regular tetrahedron; ``nan`` for a degenerate one.

    Examples
    --------
    >>> lo, hi = dihedral_angles([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    >>> float(lo[0].round(3)), float(hi[0].round(3))
    (54.736, 90.0)
    """
    cells = np.asarray(cells)
    if cells.shape[1] != 4:
        raise ValueError("dihedral_angles needs tetrahedra (4 vertices per cell); "
                         f"got {cells.shape[1]}.")
    lo = np.empty(len(cells))
    hi = np.empty(len(cells))
    for start, p in _chunks(points, cells):
        normals = []
        for k in range(4):
            a, b, c = (p[:, (k + i) % 4] for i in (1, 2, 3))
            n = np.cross(b - a, c - a)
            # outward: away from the opposite vertex k
            flip = np.einsum("mi,mi->m", n, p[:, k] - a) > 0
            n[flip] *= -1
            with np.errstate(divide="ignore", invalid="ignore"):
                n /= np.linalg.norm(n, axis=1, keepdims=True)
            normals.append(n)
        # the dihedral angle at the edge shared by faces k and l is pi - angle(n_k, n_l)
        angles = np.stack([180.0 - np.degrees(np.arccos(np.clip(
            np.einsum("mi,mi->m", normals[k], normals[m]), -1, 1)))
            for k, m in _pairs(4)], axis=1)
        lo[start:start + len(p)] = angles.min(axis=1)
        hi[start:start + len(p)] = angles.max(axis=1)
    return lo, hi


def quality_data(points: np.ndarray, cells: np.ndarray) -> dict[str, np.ndarray]:
    """Per-cell quality arrays: radius-to-edge plus angles (2-D) or dihedral angles (3-D)."""
    data = {"quality": radius_edge_ratio(points, cells)}
    if points.shape[1] == 2:
        data["min_angle"], data["max_angle"] = triangle_angles(points, cells)
    else:
        data["min_dihedral"], data["max_dihedral"] = dihedral_angles(points, cells)
    return data


def _pairs(n: int):
    return [(k, m) for k in range(n) for m in range(k + 1, n)]
