"""The proven quality bound of the template mesher: every leaf configuration, meshed.

As in the reference's Tables 3.3-3.5, but exhaustive for *this* mesher: in a tree balanced
across faces and edges, the only points a leaf's boundary can carry besides its corners
are edge midpoints and (3-D) face centres, and a face centre is a vertex only together
with the four midpoints of that face's edges (the neighbour across the face is split into
leaves of half size, all inside the image). :func:`leaf_configurations` lists every subset
of sites obeying that rule (a superset of what trees produce, so the bound is safe),
:func:`quality_table` cuts each one with the same code the mesher runs
(``_templates.cut_leaves``) and returns the distinct simplices up to the symmetries of
the cube, with their quality. Every element of every template mesh
is a translated, uniformly scaled copy of one of them (isotropic spacing), so the table's
worst values are the mesh's bounds. With anisotropic spacing every element is such a copy
stretched by the spacing, so the worst stretched template is the bound for that spacing
(:func:`quality_bounds` with ``spacing``).
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np

from ..._validation import normalize_spacing
from ..mesher import _templates_luts as luts
from ..mesher._templates import cut_leaves, template_quality
from ._quality import dihedral_angles, radius_edge_ratio, signed_volumes, triangle_angles

__all__ = ["format_lattice_bounds", "format_quality_table", "leaf_configurations",
           "quality_bounds", "quality_table"]


def _check_dim(dim) -> int:
    if dim not in (2, 3):
        raise ValueError("the quality table exists for dim 2 or 3 (the mesher's templates); "
                         f"got {dim!r}.")
    return int(dim)


def leaf_configurations(dim: int) -> np.ndarray:
    """Every set of boundary sites a leaf of an edge-balanced tree can carry.

    Parameters
    ----------
    dim : {2, 3}

    Returns
    -------
    (K, n_sites) ndarray of bool
        One row per configuration; columns follow ``SITES[dim]`` (2-D: 4 edge midpoints,
        K = 16; 3-D: 12 edge midpoints then 6 face centres).

    Examples
    --------
    >>> leaf_configurations(2).shape
    (16, 4)
    """
    d = _check_dim(dim)
    sites = luts.SITES[d]
    n_sites = len(sites)
    edge = np.array([int((s == 1).sum()) == 1 for s in sites])
    rows = np.array(list(itertools.product((False, True), repeat=n_sites)), dtype=bool) \
        if n_sites <= 12 else None
    if rows is None:
        # 3-D: enumerate edge subsets, then face centres only where all four edges are set
        edges = np.array(list(itertools.product((False, True), repeat=int(edge.sum()))), dtype=bool)
        face_idx = np.flatnonzero(~edge)
        needs = [[i for i in np.flatnonzero(edge)
                  if all(sites[i][a] == sites[f][a] for a in range(d) if sites[f][a] != 1)]
                 for f in face_idx]
        out = []
        for faces in itertools.product((False, True), repeat=len(face_idx)):
            ok = np.ones(len(edges), dtype=bool)
            for on, need in zip(faces, needs):
                if on:
                    ok &= edges[:, need].all(axis=1)
            block = np.zeros((int(ok.sum()), n_sites), dtype=bool)
            block[:, edge] = edges[ok]
            block[:, face_idx] = faces
            out.append(block)
        rows = np.concatenate(out)
    return rows


def _symmetries(d: int):
    """The 2^d d! symmetries of the cube [0, 2]^d as (permutation, flip) pairs."""
    return [(perm, flips) for perm in itertools.permutations(range(d))
            for flips in itertools.product((False, True), repeat=d)]


def _canonical(points: np.ndarray, symmetries) -> tuple:
    """Canonical form of a set of lattice points in [0, 2]^d under the cube's symmetries."""
    def key(perm, flips) -> tuple:
        q = points[..., list(perm)].copy()
        q[..., list(flips)] = 2 - q[..., list(flips)]
        return tuple(sorted(map(tuple, q.reshape(-1, q.shape[-1]).tolist())))

    return min(key(perm, flips) for perm, flips in symmetries)


def _count_up_to_symmetry(configs: np.ndarray, d: int, symmetries) -> int:
    """Number of configurations distinct under the cube's symmetries (vectorised)."""
    sites = luts.SITES[d].astype(np.int64)
    index = {tuple(s): i for i, s in enumerate(sites.tolist())}
    weights = np.left_shift(np.int64(1), np.arange(len(sites), dtype=np.int64))
    codes = []
    for perm, flips in symmetries:
        q = sites[:, list(perm)].copy()
        q[:, list(flips)] = 2 - q[:, list(flips)]
        image = np.array([index[tuple(p)] for p in q.tolist()])  # site i -> site image[i]
        moved = np.zeros_like(configs)
        moved[:, image] = configs
        codes.append(moved.astype(np.int64) @ weights)
    return int(len(np.unique(np.min(codes, axis=0))))


def quality_table(dim: int) -> list[dict]:
    """Mesh every leaf configuration with the templates; list the distinct simplices.

    Parameters
    ----------
    dim : {2, 3}

    Returns
    -------
    list of dict
        One row per distinct template simplex (up to rotations and reflections of the
        cube), worst ratio first, over every configuration cut by every diagonal rule
        (``_templates_luts``). Keys: ``dim``, ``kind`` ("kuhn", "five": the 3-D plain leaf
        of five tetrahedra, "cone", or "table": only in the sited-leaf table, see
        ``_templates_luts.LeafTable``), ``vertices``
        (coordinates on a leaf of side 2, as in the reference's tables),
        ``circumradius``, ``shortest_edge``, ``radius_edge_ratio``, ``min_angle`` and
        ``max_angle`` (2-D, degrees) or ``min_dihedral`` and ``max_dihedral`` (3-D,
        degrees), ``n_configurations`` (configurations that use it),
        ``n_configurations_total`` and ``n_configurations_up_to_symmetry``. JSON-ready.

    Examples
    --------
    >>> rows = quality_table(2)
    >>> len(rows), round(max(r["radius_edge_ratio"] for r in rows), 4)
    (3, 0.7071)
    """
    d = _check_dim(dim)
    configs = leaf_configurations(d)
    strides = np.array([3 ** (d - 1 - a) for a in range(d)], dtype=np.int64)
    n = len(configs)
    # every configuration under every diagonal rule (variant) the mesher uses
    n_var = len(luts.VARIANTS[d])
    variant = np.repeat(np.asarray(luts.VARIANTS[d], dtype=np.int8), n)
    keys, which, template_id, _ = cut_leaves(
        np.zeros(n * n_var, np.int64), np.full(n * n_var, 2, np.int64),
        np.tile(configs, (n_var, 1)), strides, variant=variant)
    which = which % n  # the configuration, whatever the variant
    # every configuration must be cut into positive simplices filling the leaf exactly
    local = np.stack(np.unravel_index(keys, (3,) * d), axis=-1).astype(float)  # (M, d+1, d)
    pts = local.reshape(-1, d)
    cells = np.arange(len(pts)).reshape(-1, d + 1)
    vol = signed_volumes(pts, cells)
    filled = np.bincount(which, weights=vol, minlength=n)
    if not (vol > 0).all() or not np.allclose(filled, n_var * 2.0 ** d):
        raise RuntimeError("a template does not fill its leaf with positive simplices.")

    symmetries = _symmetries(d)
    n_up_to_symmetry = _count_up_to_symmetry(configs, d, symmetries)

    classes: dict[tuple, dict] = {}
    for tid in np.unique(template_id):
        simplex = np.rint(luts.TEMPLATES[d][tid] * 2).astype(np.int64)  # leaf side 2
        key = _canonical(simplex[None], symmetries)
        entry = classes.setdefault(key, {"tids": [], "simplex": simplex})
        entry["tids"].append(int(tid))
    plain_ids = {v: set(range(first, first + len(luts.PLAIN[d][v])))
                 for v, first in enumerate(luts.PLAIN_TEMPLATE_ID[d])}
    rows = []
    for entry in classes.values():
        simplex = entry["simplex"].astype(float)
        cell = np.arange(d + 1)[None]
        ratio = float(radius_edge_ratio(simplex, cell)[0])
        i, j = np.triu_indices(d + 1, 1)
        shortest = float(np.linalg.norm(simplex[j] - simplex[i], axis=1).min())
        users = np.unique(which[np.isin(template_id, entry["tids"])])
        row = {
            "dim": d,
            "kind": ("kuhn" if set(entry["tids"]) & plain_ids[0] else
                     "five" if any(set(entry["tids"]) & plain_ids[v] for v in plain_ids) else
                     "cone" if min(entry["tids"]) < luts.TABLE_FIRST_ID[d] else "table"),
            "vertices": entry["simplex"].tolist(),
            "circumradius": ratio * shortest,
            "shortest_edge": shortest,
            "radius_edge_ratio": ratio,
        }
        if d == 2:
            lo, hi = triangle_angles(simplex, cell)
            row["min_angle"], row["max_angle"] = float(lo[0]), float(hi[0])
        else:
            lo, hi = dihedral_angles(simplex, cell)
            row["min_dihedral"], row["max_dihedral"] = float(lo[0]), float(hi[0])
        row["n_configurations"] = int(len(users))
        row["n_configurations_total"] = int(n)
        row["n_configurations_up_to_symmetry"] = int(n_up_to_symmetry)
        rows.append(row)
    rows.sort(key=lambda r: (-r["radius_edge_ratio"], r["vertices"]))
    return rows


#: Value of each metric on the regular simplex, by dimension: the good end of a range.
_IDEAL = {2: {"quality": 1 / math.sqrt(3), "min_angle": 60.0, "max_angle": 60.0},
          3: {"quality": math.sqrt(6) / 4, "min_dihedral": math.degrees(math.acos(1 / 3)),
              "max_dihedral": math.degrees(math.acos(1 / 3))}}


def _ranges(d: int, worst_of) -> dict[str, tuple[float, float]]:
    """Per metric, (worst, ideal) or (ideal, worst) from ``worst_of(name, smaller_is_worse)``."""
    out = {}
    for name, ideal in _IDEAL[d].items():
        low = name.startswith("min")
        worst = worst_of(name, low)
        out[name] = (worst, ideal) if low else (ideal, worst)
    return out


@functools.cache
def _bounds(d: int) -> tuple:
    rows = quality_table(d)

    def worst_of(name, low):
        values = [r["radius_edge_ratio" if name == "quality" else name] for r in rows]
        return min(values) if low else max(values)

    return tuple(_ranges(d, worst_of).items())


def quality_bounds(dim: int, spacing=None, *, subdivide: bool = True,
                   max_aspect: float | None = None) -> dict[str, tuple[float, float]]:
    """The range every element of a template mesh lies in, per metric (the IMESH bound).

    Derived from :func:`quality_table`: each range runs from the regular simplex's value
    to the worst value over all template simplices, which is the proven bound for square
    or cubic voxels. ``QUALITY_METRICS[...].optimal_range`` holds the same numbers in
    closed form. With anisotropic `spacing` the mesher cuts voxels into nearly cubic
    lattice cells (:func:`~._lattice.choose_lattice`); its elements are the templates
    stretched by the cell size, so the worst stretched template (of every template, used
    by some leaf configuration or not: a safe bound) is the bound for that spacing. With
    ``subdivide=False`` the cells are the voxels themselves.

    Parameters
    ----------
    dim : {2, 3}
    spacing : float or sequence of float, optional
        Voxel spacing the mesh was made with (one value or one per axis). Default, or all
        values equal: the cubic bound.
    subdivide : bool
        Whether the mesh was made with the anisotropy subdivision (``mesh_labels``'s
        default) or of stretched voxels.
    max_aspect : float, optional
        The residual-aspect limit the mesh was subdivided with (``mesh_labels``'s
        `max_aspect`; default its default).

    Returns
    -------
    dict of str to (float, float)
        ``(lo, hi)`` for ``"quality"`` (radius-to-edge ratio) and ``"min_angle"``,
        ``"max_angle"`` (2-D) or ``"min_dihedral"``, ``"max_dihedral"`` (3-D, degrees):
        the keys of the mesh's ``cell_data``. A GUI shades these on its histograms.

    Raises
    ------
    ValueError
        For a `dim` other than 2 or 3, or a spacing that is not positive and finite.

    Examples
    --------
    >>> b = quality_bounds(2)
    >>> [round(x, 4) for x in b["quality"] + b["min_angle"]]
    [0.5774, 0.7071, 45.0, 60.0]
    >>> round(quality_bounds(2, spacing=(2.0, 1.0), subdivide=False)["quality"][1], 4)
    1.118
    >>> round(quality_bounds(3, spacing=(2.5, 1.0, 1.0))["quality"][1], 4)  # 2x1x1 cells
    1.3754
    """
    d = _check_dim(dim)
    spacing = normalize_spacing(spacing, d)
    if subdivide:
        from ..mesher._lattice import choose_lattice

        spacing = choose_lattice(spacing, max_aspect=max_aspect).step
    if all(abs(s / spacing[0] - 1) <= 1e-12 for s in spacing):
        return dict(_bounds(d))
    table = template_quality(d, spacing)
    return _ranges(d, lambda name, low: float(table[name].min() if low else table[name].max()))


def format_quality_table(rows: list[dict]) -> str:
    """Render :func:`quality_table` rows as a text table with the bounds they prove.

    Parameters
    ----------
    rows : list of dict
        From :func:`quality_table` (one dimension).

    Returns
    -------
    str
        A title line, one line per simplex, and a last line with the bound: the worst
        radius-to-edge ratio (beside the reference's claim) and the angle range.
    """
    if not rows:
        return "(no template simplices)"
    d = rows[0]["dim"]
    angle_cols = ("min_angle", "max_angle") if d == 2 else ("min_dihedral", "max_dihedral")
    kind = "triangle" if d == 2 else "tetrahedron"
    head = (f"{'#':>2}  {'kind':<5} {'vertices (leaf side 2)':<44} {'R':>7} {'e_min':>7} "
            f"{'R/e_min':>8} {angle_cols[0]:>12} {angle_cols[1]:>12} {'configs':>8}")
    lines = [
        f"IMESH template {kind}s in {d}-D: {rows[0]['n_configurations_total']} leaf "
        f"configurations ({rows[0]['n_configurations_up_to_symmetry']} up to symmetry), "
        f"{len(rows)} distinct simplices up to symmetry"
        + (" (each configuration cut under both face-diagonal rules, parity and lowest "
           "corner)" if d == 3 else ""),
        head,
        "-" * len(head),
    ]
    for k, r in enumerate(rows, 1):
        verts = " ".join("(" + ",".join(str(c) for c in v) + ")" for v in r["vertices"])
        lines.append(f"{k:>2}  {r['kind']:<5} {verts:<44} {r['circumradius']:7.4f} "
                     f"{r['shortest_edge']:7.4f} {r['radius_edge_ratio']:8.4f} "
                     f"{r[angle_cols[0]]:12.3f} {r[angle_cols[1]]:12.3f} "
                     f"{r['n_configurations']:>8}")
    worst = max(r["radius_edge_ratio"] for r in rows)
    lo = min(r[angle_cols[0]] for r in rows)
    hi = max(r[angle_cols[1]] for r in rows)
    what = "angles" if d == 2 else "dihedral angles"
    claim = "sqrt(5)/2 = 1.1180" if d == 2 else "sqrt(29)/4 = 1.3463"
    lines.append(f"bound: radius-to-edge ratio <= {worst:.4f} (reference's claim {claim}); "
                 f"{what} in [{lo:.3f}, {hi:.3f}] deg")
    return "\n".join(lines)


def format_lattice_bounds(dim: int, aspects: list[dict], lattice=None, choices=None) -> str:
    """The bound per residual aspect as text, and for one spacing what each `max_aspect`
    gives (the chosen row marked).

    Parameters
    ----------
    dim : {2, 3}
    aspects : list of dict
        :func:`~._lattice.aspect_table` rows.
    lattice : Lattice, optional
        The lattice chosen for a spacing (:func:`~._lattice.choose_lattice`).
    choices : list of dict, optional
        :func:`~._lattice.lattice_choices` for that spacing.
    """
    from ..mesher._lattice import ASPECT_LIMIT

    angle = "dihedral angles" if dim == 3 else "angles"
    lines = ["\nbounds on lattice cells of residual aspect A (max/min cell size): anisotropic "
             f"voxels are cut into the fewest cells with A <= --max-aspect (default "
             f"{ASPECT_LIMIT}) unless --no-subdivide",
             f"{'A':>6s} {'ratio <=':>9s} {angle + ' (deg)':>22s}"]
    lines += [f"{r['aspect']:6.2f} {r['worst_ratio']:9.4f} {r['min_angle']:10.2f} .. "
              f"{r['max_angle']:7.2f}" for r in aspects]
    if lattice is None:
        return "\n".join(lines)
    lines += [(f"\nspacing {' x '.join(f'{s:g}' for s in lattice.spacing)}: the lattice for "
               "each --max-aspect (elements: about the interface cells per voxel face, "
               "against cubic voxels of the same image)"),
              (f"{'--max-aspect':>16s} {'cells per voxel':>18s} {'residual A':>10s} "
               f"{'ratio <=':>9s} {angle + ' (deg)':>24s} {'elements':>9s}")]
    for r in choices:
        upper = r["max_aspect_below"]
        span = (f">= {r['max_aspect_from']:.4g}" if upper is None
                else f"{r['max_aspect_from']:.4g} .. <{upper:.4g}")
        cells = " x ".join(map(str, r["factors"])) + f" = {r['cells_per_voxel']}"
        b = r["bounds"]
        mark = "  <- chosen" if tuple(r["factors"]) == tuple(lattice.factors) else ""
        lines.append(f"{span:>16s} {cells:>18s} {r['residual_aspect']:10.4f} "
                     f"{b['worst_ratio']:9.4f} {b['min_angle']:11.2f} .. {b['max_angle']:7.2f}"
                     f" {'x' + format(r['interface_cells_per_voxel_face'], '.3g'):>9s}{mark}")
    d = lattice.describe()
    lines.append(f"chosen (--max-aspect {lattice.max_aspect:g}): "
                 f"{' x '.join(map(str, lattice.factors))} cells per voxel, residual aspect "
                 f"{d['residual_aspect']:.4f}: ratio <= {d['bounds']['worst_ratio']:.4f}, "
                 f"{angle} {d['bounds']['min_angle']:.2f} to {d['bounds']['max_angle']:.2f}")
    return "\n".join(lines)
