"""IMESH: from a label image to a conforming simplex mesh on a balanced 2^d-tree.

Steps (reference ch. 3, with the last step replaced): region tree -> 2:1 balance ->
vertices (leaf corners) -> simplices. Two ways to make simplices:

* ``"template"`` (default): the reference's *dictionary method* (its future work). Each
  balanced leaf is cut by look-up tables (``_templates_luts.py``) according to which of
  its edge midpoints and face centres are vertices. The tree is balanced across faces and
  edges (3-D) so that these are the only points a leaf's boundary can carry. Everything is
  integer arithmetic on the lattice of pixel corners (leaf centres and new face centres of
  leaves of level >= 1 are pixel corners too; level-0 leaves never carry sites), so
  vertices are deduplicated by integer keys and no floating-point predicate is evaluated.
  Because every element is a scaled copy of a template, its quality is a table look-up.
* ``"delaunay"``: the reference's own step, scipy's Qhull Delaunay of the leaf corners of
  the face-balanced tree, kept for comparison. Zero-volume simplices are dropped and
  counted, and the mesh checks are run and stored in ``info`` so the result is reported
  as it is.
"""

from __future__ import annotations

import itertools
import math
import time

import numpy as np

from .._tree import RegionTree, _build_tree
from .._validation import as_labels, normalize_spacing
from . import _templates_luts as luts
from ._balance import balance_tree, count_balanced_leaves
from ._checks import _check_mesh, count_excluded
from ._quality import dihedral_angles, radius_edge_ratio, signed_volumes, triangle_angles
from ._types import Mesh

__all__ = ["cut_leaves", "mesh_labels", "mesh_tree"]

METHODS = ("template", "delaunay")


def mesh_labels(labels, *, method: str = "template", exclude=(), spacing=None,
                material_names: dict[int, str] | None = None) -> Mesh:
    """Mesh a 2-D or 3-D label image into triangles or tetrahedra, one material each.

    Parameters
    ----------
    labels : (M, N[, P]) array_like of int
        Label image, any size per axis (not only powers of two). Whole-valued floats are
        accepted; negative labels are not.
    method : {"template", "delaunay"}
        ``"template"``: look-up-table mesher, conforming by construction, worst
        radius-to-edge ratio 1/sqrt(2) in 2-D and sqrt(5)/2 in 3-D (see
        :func:`quality_table`). ``"delaunay"``: the reference's Qhull step, for comparison;
        not conforming in 3-D.
    exclude : iterable of int
        Materials not to mesh (e.g. ``(0,)`` for background); their faces become boundary.
    spacing : float or sequence of float, optional
        Pixel/voxel size per axis (napari layer ``scale``); points are placed at
        ``index * spacing``. Default 1.
    material_names : dict of int to str, optional
        Names carried to the mesh (used by the writers).

    Returns
    -------
    Mesh
        ``points (N, d) float64`` in physical units, ``cells (M, d+1) intp`` positively
        oriented, ``material (M,) int64``, ``cell_data`` with ``quality`` (radius-to-edge),
        ``level`` and ``leaf`` (index of the balanced leaf), and ``min_angle``/``max_angle`` (2-D) or
        ``min_dihedral``/``max_dihedral`` (3-D) in degrees; ``info`` holds counts, the worst
        ratio, the angle range and seconds per step.

    Notes
    -----
    The quality bounds hold in index space (isotropic voxels); anisotropic `spacing`
    stretches every template by the same factors, and the per-element metrics are those of
    the stretched elements. Template elements per leaf: d! (Kuhn) when no edge midpoint or
    face centre of the leaf is a vertex, else one cone simplex per boundary segment or face
    triangle (2-D: 5-8; 3-D: 12-48).

    Raises
    ------
    ValueError
        For 1-D or 4-D+ input, non-integer or negative labels, an empty image, an unknown
        method, or when every pixel is excluded.
    TypeError
        For non-numeric label arrays.

    Examples
    --------
    >>> m = mesh_labels(np.array([[1, 1], [1, 2]]))
    >>> m.n_cells, sorted(set(m.material.tolist()))
    (8, [1, 2])
    >>> float(m.quality.max().round(4))
    0.7071
    """
    lab, spacing_t, exclude_arr = _mesh_arguments(labels, method=method, exclude=exclude,
                                                   spacing=spacing)
    mesh, tree = _mesh_labels(lab, method=method, exclude=exclude_arr, spacing=spacing_t,
                              material_names=material_names)
    if method == "delaunay":  # report the reference's step as it is
        t = time.perf_counter()
        checks = _check_mesh(mesh, lab, exclude_arr, tree)
        mesh.info["checks"] = checks.to_dict()
        mesh.info["conforming"] = checks.conforming
        mesh.info["seconds"]["checks"] = round(time.perf_counter() - t, 6)
    return mesh


def _exclude_array(exclude) -> np.ndarray:
    """`exclude` (an id or ids) as a sorted unique int64 array, or TypeError."""
    arr = np.unique(np.asarray(list(exclude) if not np.isscalar(exclude) else [exclude]))
    if arr.size and arr.dtype.kind not in "iu":
        raise TypeError(f"exclude must hold integer material ids; got {exclude!r}.")
    return arr.astype(np.int64)


def _mesh_arguments(labels, *, method, exclude, spacing, name: str = "labels"):
    """The door of :func:`mesh_labels`: (labels, spacing tuple, exclude array), checked.

    The labels keep their dtype (no copy for integer input). The command line calls
    this with the file's name, then :func:`_mesh_labels`.
    """
    lab = as_labels(labels, name=name, min_ndim=2, max_ndim=3)
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}.")
    spacing_t = normalize_spacing(spacing, lab.ndim)
    exclude_arr = _exclude_array(exclude)
    if exclude_arr.size and count_excluded(lab, exclude_arr) == lab.size:
        raise ValueError(
            f"every pixel is excluded (labels present: {np.unique(lab).tolist()}, "
            f"exclude={exclude_arr.tolist()}); nothing is left to mesh. Exclude fewer materials."
        )
    return lab, spacing_t, exclude_arr


def _mesh_labels(lab: np.ndarray, *, method: str, exclude: np.ndarray, spacing: tuple,
                 material_names: dict | None = None) -> tuple[Mesh, RegionTree]:
    """The worker behind :func:`mesh_labels`; arguments come from :func:`_mesh_arguments`.

    Returns the mesh and the region tree of `lab`, which the checks can reuse.
    """
    t0 = time.perf_counter()
    tree = _build_tree(lab)
    seconds = {"tree": time.perf_counter() - t0}
    mesh = _mesh_tree(tree, method=method, exclude=exclude, spacing=spacing,
                      material_names=_names(material_names), connectivity=None,
                      report_face_balance=False, seconds=seconds)
    return mesh, tree


def _names(material_names) -> dict[int, str]:
    return {int(k): str(v) for k, v in (material_names or {}).items()}


def mesh_tree(tree: RegionTree, *, method: str = "template", exclude=(), spacing=None,
              material_names: dict[int, str] | None = None, connectivity: int | None = None,
              report_face_balance: bool = False) -> Mesh:
    """Mesh the leaves of an (unbalanced) region tree.

    Parameters
    ----------
    tree : RegionTree
        From :func:`~napari_swa_imesh.build_tree` of a 2-D or 3-D label image.
    method, exclude, spacing, material_names
        As for :func:`mesh_labels`.
    connectivity : int, optional
        Balance used (scipy's convention): templates need at least ``d - 1`` (faces and,
        in 3-D, edges; the default), ``d`` adds corners; the Delaunay method defaults to
        faces (1).
    report_face_balance : bool
        Also count the leaves a face-only balance would give (a second balance pass) and
        report them in ``info["n_leaves_face_balanced"]``, with the extra leaves and
        elements the stronger balance costs. Off by default: these fields are then None
        unless the balance used is the face balance itself.

    Returns
    -------
    Mesh
        As :func:`mesh_labels` returns (``info["seconds"]`` without the tree).

    Examples
    --------
    >>> from napari_swa_imesh import build_tree
    >>> mesh_tree(build_tree(np.array([[1, 1], [1, 2]]))).n_cells
    8
    """
    if not isinstance(tree, RegionTree):
        raise TypeError(f"tree must be a RegionTree (from build_tree); got {type(tree).__name__}.")
    d = tree.ndim
    if d not in (2, 3):
        raise ValueError(f"the mesher takes 2-D or 3-D trees; got a {d}-D tree.")
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}.")
    if connectivity is not None and connectivity not in range(1, d + 1):
        raise ValueError(f"connectivity must be 1..{d} for a {d}-D tree; got {connectivity!r}.")
    if method == "template" and connectivity is not None and connectivity < d - 1:
        raise ValueError(f"templates need balance across faces and edges (connectivity >= {d - 1}).")
    return _mesh_tree(tree, method=method, exclude=_exclude_array(exclude),
                      spacing=normalize_spacing(spacing, d), material_names=_names(material_names),
                      connectivity=connectivity, report_face_balance=bool(report_face_balance),
                      seconds={})


def _mesh_tree(tree: RegionTree, *, method: str, exclude: np.ndarray, spacing: tuple,
               material_names: dict[int, str], connectivity: int | None,
               report_face_balance: bool, seconds: dict) -> Mesh:
    """The worker behind :func:`mesh_tree` and :func:`mesh_labels`: trusted arguments;
    `seconds` holds the steps already timed (the tree) and receives the others."""
    d = tree.ndim
    if connectivity is None:
        connectivity = 1 if method == "delaunay" else max(1, d - 1)

    t = time.perf_counter()
    bal = balance_tree(tree, connectivity=connectivity)
    seconds["balance"] = time.perf_counter() - t
    meshed = bal.inside & ~np.isin(bal.label, exclude)
    info = {
        "method": method,
        "dim": d,
        "shape": list(tree.shape),
        "spacing": list(spacing),
        "exclude": exclude.tolist(),
        "balance": {1: "faces", 2: "faces+edges", 3: "faces+edges+corners"}.get(
            connectivity, f"connectivity {connectivity}"),
        "n_leaves_tree": int(np.count_nonzero(tree.inside)),
        "n_leaves_balanced": int(np.count_nonzero(bal.inside)),
        "n_leaves_meshed": int(np.count_nonzero(meshed)),
    }
    # a second balance pass, only to say what the stronger balance cost: opt-in
    if connectivity == 1:
        info["n_leaves_face_balanced"] = info["n_leaves_balanced"]
    elif report_face_balance:
        t = time.perf_counter()
        info["n_leaves_face_balanced"] = count_balanced_leaves(tree, connectivity=1)
        seconds["face_balance_count"] = time.perf_counter() - t
    else:
        info["n_leaves_face_balanced"] = None

    if method == "template":
        points, cells, leaf, template_id, vseconds = _template_mesh(bal, meshed)
        seconds.update(vseconds)
        t = time.perf_counter()
        table = _template_quality(d, spacing)
        template_id = template_id.astype(np.intp)  # once, not once per look-up
        cell_data = {name: values[template_id] for name, values in table.items()}
        del template_id
        seconds["quality"] = time.perf_counter() - t
        info["n_kuhn_leaves"] = int(vseconds.pop("_n_kuhn"))
        seconds.pop("_n_kuhn", None)
    else:
        points, cells, leaf, cell_data, dinfo, vseconds = _delaunay_mesh(bal, meshed)
        seconds.update(vseconds)
        info.update(dinfo)

    t = time.perf_counter()
    if any(s != 1.0 for s in spacing):
        points *= np.asarray(spacing)  # points is the mesher's own array: scale in place
    material = bal.label[leaf]
    cell_data = {"quality": cell_data.pop("quality"), "level": bal.level[leaf],
                 "leaf": leaf, **cell_data}
    seconds["assemble"] = time.perf_counter() - t
    mesh = Mesh._trusted(points, cells, material, cell_data, spacing=spacing,
                         shape=tuple(tree.shape), material_names=dict(material_names or {}),
                         info=info)

    t = time.perf_counter()
    n_el = mesh.n_cells
    info["n_vertices"] = int(len(points))
    info["n_elements"] = n_el
    info["elements_per_leaf"] = n_el / max(1, info["n_leaves_meshed"])
    if info["n_leaves_face_balanced"] is None:
        info["balance_extra_leaves"] = info["balance_element_cost"] = None
    else:
        extra = info["n_leaves_balanced"] - info["n_leaves_face_balanced"]
        info["balance_extra_leaves"] = extra
        # estimate: leaves added by the stronger balance times the mean elements per leaf
        info["balance_element_cost"] = int(round(extra * info["elements_per_leaf"]))
    info["worst_ratio"] = float(np.max(mesh.quality, initial=0.0))
    if d == 2:
        info["min_angle"] = float(np.nanmin(cell_data["min_angle"]))
        info["max_angle"] = float(np.nanmax(cell_data["max_angle"]))
        info["angle_range"] = [info["min_angle"], info["max_angle"]]
    elif d == 3:
        info["min_dihedral"] = float(np.nanmin(cell_data["min_dihedral"]))
        info["max_dihedral"] = float(np.nanmax(cell_data["max_dihedral"]))
        info["angle_range"] = [info["min_dihedral"], info["max_dihedral"]]
    seconds["stats"] = time.perf_counter() - t
    info["seconds"] = {k: round(v, 6) for k, v in seconds.items()}
    info["seconds_total"] = round(sum(v for k, v in seconds.items() if k != "checks"), 6)
    return mesh


# --------------------------------------------------------------------------- templates


def _lattice(tree: RegionTree):
    """Shape and strides of the lattice of pixel corners of the padded grid.

    Keys are intp: numpy would convert any other index dtype on every gather.
    """
    shape = tuple(n + 1 for n in tree.padded_shape)
    strides = np.array([math.prod(shape[a + 1:]) for a in range(len(shape))], dtype=np.intp)
    return shape, strides


def _mark_corners(tree: RegionTree, select: np.ndarray, shape, strides) -> np.ndarray:
    """Flat bool lattice: True at every corner of the selected leaves (one pass per level)."""
    d = tree.ndim
    is_vertex = np.zeros(math.prod(shape), dtype=bool)
    corner_keys = np.array(list(itertools.product((0, 1), repeat=d)), strides.dtype) @ strides
    for lev in np.unique(tree.level[select]):
        sel = select & (tree.level == lev)
        okey = tree.origin[sel].astype(strides.dtype) @ strides
        is_vertex[(okey[:, None] + (corner_keys << int(lev))[None]).ravel()] = True
    return is_vertex


def _template_mesh(bal: RegionTree, meshed: np.ndarray):
    """Cut every meshed leaf by the look-up tables.

    Returns points (index space), cells, leaf index and template id per element, and the
    seconds spent per step.
    """
    d = bal.ndim
    seconds = {}
    t = time.perf_counter()
    shape, strides = _lattice(bal)
    # vertices are the corners of every leaf inside the image, whatever its material:
    # then a face centre that is a vertex always comes with its four edge midpoints
    is_vertex = _mark_corners(bal, bal.inside, shape, strides)
    leaves = np.flatnonzero(meshed)
    kd = strides.dtype
    level = bal.level[leaves].astype(kd)
    okey = bal.origin[leaves].astype(kd) @ strides  # (L,) lattice key of each leaf's lowest corner
    size = np.left_shift(kd.type(1), level)
    half = size >> 1
    site_keys = luts.SITES[d].astype(kd) @ strides  # (n_sites,)
    hanging = np.zeros((len(leaves), len(site_keys)), dtype=bool)
    coarse = np.flatnonzero(level >= 1)  # level-0 leaves have no sites: no leaf is smaller
    site_of_coarse = okey[coarse, None] + half[coarse, None] * site_keys[None]  # (Lc, n_sites)
    hanging[coarse] = is_vertex[site_of_coarse]
    kuhn = ~hanging.any(axis=1)
    # the points elements use: corners of meshed leaves, the sites they carry, and the
    # new points of the templates (marked without scattering every element's keys)
    used = is_vertex if meshed.sum() == bal.inside.sum() else _mark_corners(bal, meshed, shape, strides)
    used[site_of_coarse[hanging[coarse]]] = True
    del site_of_coarse
    seconds["vertices"] = time.perf_counter() - t

    t = time.perf_counter()
    cells, which, template_of, _ = cut_leaves(okey, size, hanging, strides, used=used)
    leaf_of = leaves[which]  # intp: it indexes the leaf arrays again below
    del which
    seconds["simplices"] = time.perf_counter() - t

    t = time.perf_counter()
    points = np.stack(np.unravel_index(np.flatnonzero(used), shape), axis=1).astype(np.float64)
    seconds["numbering"] = time.perf_counter() - t
    seconds["_n_kuhn"] = int(kuhn.sum())
    return points, cells, leaf_of, template_of, seconds


def cut_leaves(okey: np.ndarray, size: np.ndarray, hanging: np.ndarray, strides: np.ndarray,
               *, used: np.ndarray | None = None):
    """Cut leaves by the look-up tables; the dictionary step, shared with the quality table.

    Parameters
    ----------
    okey : (L,) ndarray of int32 or int64
        Lattice key (``coords @ strides``) of each leaf's lowest corner.
    size : (L,) ndarray of the same dtype
        Leaf side in lattice units; leaves with a site present must have an even side.
    hanging : (L, n_sites) ndarray of bool
        Which of ``SITES[d]`` are vertices, per leaf.
    strides : (d,) ndarray of the same dtype
        Strides of the lattice; keys are linear, so a template's key is
        ``okey + scale * (local @ strides)``.
    used : (n_lattice,) ndarray of bool, optional
        Flat lattice marking the corners and sites present. When given, the templates' new
        points are marked in it, and elements come back as vertex numbers (the rank of the
        key among the marked points, i.e. ``cumsum(used) - 1``) instead of keys, so the
        big key array is never built.

    Returns
    -------
    keys : (M, d+1) ndarray of intp
        Lattice key (or vertex number, with `used`) of every element vertex, positively
        oriented.
    which : (M,) ndarray of int32 (int64 for 2^31 leaves or more)
        Index (into the L leaves) of the leaf each element cuts.
    template_id : (M,) ndarray of int16
        Index into ``TEMPLATES[d]``.
    new_points : (K,) ndarray of the keys' dtype
        Keys of the points the templates add (leaf centres, face centres of fans), with
        repeats; every other element vertex is a leaf corner or a site present.
    """
    d = len(strides)
    kd = strides.dtype
    wd = np.int32 if len(okey) < 2**31 else np.int64
    half = size >> 1
    kuhn = ~hanging.any(axis=1)
    nk = np.flatnonzero(kuhn)
    other = np.flatnonzero(~kuhn)
    # group the other leaves by the case of each face: (face, case, members)
    groups = []
    for f, fsites in enumerate(luts.FACE_SITES[d]):
        # uint8 codes: numpy's stable sort is a radix sort for them
        code = np.zeros(len(other), dtype=np.uint8)
        for bit, site in enumerate(fsites):
            code |= hanging[other, site].astype(np.uint8) << np.uint8(bit)
        order = np.argsort(code, kind="stable")
        bounds = np.searchsorted(code[order], np.arange((1 << len(fsites)) + 1), side="left")
        for case in range(1 << len(fsites)):
            if bounds[case + 1] > bounds[case]:
                if len(luts.FACE_LUT[d][f][case]) == 0:
                    raise RuntimeError(f"leaf configuration outside the look-up table (face {f}, "
                                       f"case {case}); the tree is not balanced as assumed.")
                groups.append((f, case, other[order[bounds[case]:bounds[case + 1]]]))
    n_kuhn = len(luts.KUHN[d])
    total = len(nk) * n_kuhn + sum(len(sel) * len(luts.FACE_LUT[d][f][c]) for f, c, sel in groups)
    new_points = []
    for f, case, sel in groups:
        new_local = _new_points(d, f, case)
        if len(new_local):
            new_keys = new_local.astype(kd) @ strides
            new_points.append((okey[sel, None] + half[sel, None] * new_keys[None]).ravel())
    new_points = np.concatenate(new_points) if new_points else np.zeros(0, kd)
    vertex_id = None
    if used is not None:
        used[new_points] = True
        vertex_id = np.cumsum(used, dtype=np.intp)
        vertex_id -= 1
    # write every block straight into its slice of the outputs (no concatenation copies)
    keys = np.empty((total, d + 1), dtype=kd)
    which = np.empty(total, dtype=wd)
    template_of = np.empty(total, dtype=np.int16)

    def emit(start, sel, scale, local_keys, first_template):
        n, t = len(sel), len(local_keys)
        block = keys[start:start + n * t].reshape(n, t, d + 1)
        if vertex_id is None:
            np.multiply(scale[sel, None, None], local_keys[None], out=block)
            block += okey[sel, None, None]
        else:
            lattice_keys = scale[sel, None, None] * local_keys[None]
            lattice_keys += okey[sel, None, None]
            np.take(vertex_id, lattice_keys, out=block)
        which[start:start + n * t].reshape(n, t)[:] = sel[:, None]
        template_of[start:start + n * t].reshape(n, t)[:] = np.arange(first_template, first_template + t)
        return start + n * t

    # Kuhn leaves: d! simplices in units of the leaf side
    start = emit(0, nk, size, luts.KUHN[d].astype(kd) @ strides, 0)
    # other leaves: every face by its own case, coned to the leaf centre (unit: half side)
    for f, case, sel in groups:
        lut = luts.FACE_LUT[d][f][case]
        start = emit(start, sel, half, lut.astype(kd) @ strides, luts.FACE_TEMPLATE_ID[d][f][case])
    return keys, which, template_of, new_points


def _new_points(d: int, face: int, case: int) -> np.ndarray:
    """(k, d) local points of a face case that are neither corners nor sites present."""
    present = {tuple(luts.SITES[d][s]) for i, s in enumerate(luts.FACE_SITES[d][face]) if case >> i & 1}
    pts = {tuple(p) for p in luts.FACE_LUT[d][face][case].reshape(-1, d).tolist()}
    new = [p for p in sorted(pts) if p not in present and any(c == 1 for c in p)]
    return np.array(new, dtype=np.int64).reshape(-1, d)


def _template_quality(d: int, spacing: tuple[float, ...]) -> dict[str, np.ndarray]:
    """Quality of every template simplex once scaled by `spacing`: (n_templates,) arrays."""
    tpl = luts.TEMPLATES[d] * np.asarray(spacing)  # (n, d+1, d)
    pts = tpl.reshape(-1, d)
    cells = np.arange(len(pts)).reshape(-1, d + 1)
    return _quality_data(pts, cells)


def _quality_data(points: np.ndarray, cells: np.ndarray) -> dict[str, np.ndarray]:
    """Per-cell quality arrays: radius-to-edge plus angles (2-D) or dihedral angles (3-D)."""
    data = {"quality": radius_edge_ratio(points, cells)}
    if points.shape[1] == 2:
        data["min_angle"], data["max_angle"] = triangle_angles(points, cells)
    else:
        data["min_dihedral"], data["max_dihedral"] = dihedral_angles(points, cells)
    return data


# ---------------------------------------------------------------------------- delaunay


def _delaunay_mesh(bal: RegionTree, meshed: np.ndarray):
    """The reference's step: Qhull Delaunay of the unique corners of the meshed leaves."""
    from scipy.spatial import Delaunay

    d = bal.ndim
    seconds = {}
    t = time.perf_counter()
    shape, strides = _lattice(bal)
    is_vertex = _mark_corners(bal, meshed, shape, strides)
    points = np.stack(np.unravel_index(np.flatnonzero(is_vertex), shape), axis=1).astype(np.float64)
    del is_vertex
    seconds["vertices"] = time.perf_counter() - t

    t = time.perf_counter()
    simplices = Delaunay(points).simplices.astype(np.intp)
    seconds["simplices"] = time.perf_counter() - t

    t = time.perf_counter()
    vol = signed_volumes(points, simplices)
    flip = vol < 0
    simplices[flip, 0], simplices[flip, 1] = simplices[flip, 1], simplices[flip, 0].copy()
    scale = float(np.abs(vol).max()) if vol.size else 1.0
    zero = np.abs(vol) <= 1e-12 * scale
    # material of the leaf under each centroid; a centroid in padding or an excluded
    # material means the simplex lies outside the meshed region (hull of a concave set)
    centroid = points[simplices].mean(axis=1)
    pix = np.minimum(np.floor(centroid).astype(np.int64), np.array(bal.padded_shape) - 1)
    leaf_map = bal.to_image(values=np.arange(len(bal)), crop=False)
    leaf = leaf_map[tuple(pix.T)]
    keep = ~zero & meshed[leaf]
    info = {"n_delaunay_simplices": int(len(simplices)), "n_zero_volume": int(zero.sum()),
            "n_outside_dropped": int((~zero & ~meshed[leaf]).sum())}
    simplices, leaf = simplices[keep], leaf[keep]
    cell_data = _quality_data(points, simplices)
    # drop vertices no kept simplex uses
    used = np.zeros(len(points), bool)
    used[simplices.ravel()] = True
    new_id = np.cumsum(used) - 1
    seconds["quality"] = time.perf_counter() - t
    return points[used], new_id[simplices].astype(np.intp), leaf, cell_data, info, seconds
