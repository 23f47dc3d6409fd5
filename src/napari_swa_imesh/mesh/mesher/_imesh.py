"""IMESH: from a label image to a conforming simplex mesh on a balanced 2^d-tree.

Steps (reference ch. 3, with the last step replaced): region tree -> 2:1 balance ->
vertices (leaf corners) -> simplices. Two ways to make simplices:

* ``"template"`` (default, ``_templates.py``): the reference's *dictionary method* (its
  future work). Each balanced leaf is cut by look-up tables according to which of its
  edge midpoints and face centres are vertices. The tree is balanced across faces and
  edges (3-D) so that these are the only points a leaf's boundary can carry.
* ``"delaunay"`` (``_delaunay.py``): the reference's own step, scipy's Qhull Delaunay of
  the leaf corners of the face-balanced tree, kept for comparison. Zero-volume simplices
  are dropped and counted, and :func:`mesh_labels` runs the mesh checks and stores them
  in ``info`` so the result is reported as it is.

This module is the door (arguments checked once) and the assembly of the result: points
in physical units, per-element data, counts and seconds in ``info``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ._tree import RegionTree, _build_tree
from ..._validation import as_labels, normalize_spacing
from ._balance import balance_tree, count_balanced_leaves
from ..checks._checks import _check_mesh, count_excluded
from ._delaunay import delaunay_mesh
from ._coarsen import check_coarsen, coarsen_labels
from ._lattice import Lattice, choose_lattice, lattice_tree
from ..checks._leaf_facets import MadeLattice
from ._templates import template_mesh, template_quality
from ..model._types import Mesh
from ..model._world import world_from_affine

__all__ = ["mesh_labels", "mesh_tree"]

METHODS = ("template", "delaunay")


def mesh_labels(labels, *, method: str = "template", exclude=(), spacing=None,
                material_names: dict[int, str] | None = None, affine=None, refine: int = 0,
                max_size: float | None = None, subdivide: bool = True,
                coarsen: int = 0, periodic: bool = False,
                max_aspect: float | None = None) -> Mesh:
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
    affine : (d+1, d+1) or (4, 4) array_like, optional
        Index-to-world affine of `labels`, voxel centres at integer indices (NIfTI:
        nibabel's ``img.affine``, :func:`napari_swa_imesh.io.read_affine`). The mesh is
        made with the affine's voxel sizes as spacing and carries the rest as
        ``Mesh.world``, so every file gets world coordinates (see :mod:`._world`;
        rotations, flips and an origin included). Give it instead of `spacing`.
    refine : int
        Interface refinement ``0 .. 4``: elements sharing a facet with a material
        interface are at most ``2**-refine`` voxels along every axis (cells of the
        anisotropy subdivision count toward it); the interior coarsens as before.
    max_size : float, optional
        Longest element edge allowed (physical units); larger leaves are split.
    subdivide : bool
        Cut anisotropic voxels into nearly cubic lattice cells (integer factors per axis,
        the fewest cells with residual aspect at most `max_aspect`) so the quality bounds
        hold in physical space. Off: the stretched voxels are meshed as they are, without
        a bound.
    coarsen : int
        ``0 .. 5``: mesh the labels in blocks of ``2**coarsen`` voxels (each block takes
        its majority label), for large smooth volumes. Boundaries move to that grid; the
        per-material volume change is in ``info["coarsen"]`` and a material that no block
        keeps is named in a warning.
    periodic : bool
        Give opposite faces of the image box the same vertices and facets (translated),
        for periodic boundary conditions: elements touching the box are one lattice cell.
    max_aspect : float, optional
        Largest residual aspect of the lattice cells (default ``ASPECT_LIMIT`` = 1.25; 3-D
        bound there: radius-to-edge <= 1.3754, dihedral angles 29.5-131.5 deg). Larger:
        fewer cells per voxel, looser bound (``swa-imesh bounds --spacing`` lists them).

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
    The mesher works on the lattice of :func:`choose_lattice` (``info["lattice"]``): the
    voxels themselves for cubic spacing without refinement. The per-element metrics are
    those of the physical elements; ``level`` counts lattice cells. Template elements per
    leaf, when no edge midpoint or face centre of the leaf is a vertex: 2 in 2-D, 5 in 3-D
    (6, Kuhn's, in a periodic mesh with an odd extent: ``info["diagonal_rule"]``); else
    one cone simplex per boundary segment or face triangle (2-D: 5-8; 3-D: 12-48), or in
    3-D the fewer tetrahedra of the leaf table where it has the configuration (17-40;
    ``_templates_luts.LeafTable``).

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

    Placed by an affine (x flipped, 2 x 3 voxels; voxel (0, 0) centred at the origin):

    >>> from napari_swa_imesh.mesh import to_meshio
    >>> placed = mesh_labels(np.ones((1, 2), int), affine=np.diag([-2.0, 3.0, 1.0]))
    >>> placed.spacing
    (2.0, 3.0)
    >>> xy = to_meshio(placed).points
    >>> xy.min(axis=0).tolist(), xy.max(axis=0).tolist()
    ([-1.0, -1.5], [1.0, 4.5])
    """
    lab, spacing_t, exclude_arr = _mesh_arguments(labels, method=method, exclude=exclude,
                                                   spacing=spacing)
    world = None
    if affine is not None:
        if spacing is not None:
            raise ValueError("give spacing or affine, not both: the mesh takes its spacing "
                             "from the affine's voxel sizes.")
        spacing_t, world = world_from_affine(affine, lab.ndim)
    lattice, max_size, coarsen = resolution_arguments(
        spacing_t, method=method, refine=refine, max_size=max_size, subdivide=subdivide,
        coarsen=coarsen, max_aspect=max_aspect)
    check_periodic(method, periodic)
    lab, coarse_report = coarsen_labels(lab, coarsen, exclude_arr)
    mesh, tree = _mesh_labels(lab, method=method, exclude=exclude_arr, spacing=spacing_t,
                              material_names=material_names, lattice=lattice,
                              max_size=max_size, periodic=bool(periodic))
    mesh.world = world
    if coarsen:
        mesh.info["coarsen"] = coarse_report
        warn_lost_materials(coarse_report, mesh.material_names)
    if method == "delaunay":  # report the reference's step as it is
        t = time.perf_counter()
        checks = _check_mesh(mesh, lab, exclude_arr, tree)
        mesh.info["checks"] = checks.to_dict()
        mesh.info["conforming"] = checks.conforming
        mesh.info["seconds"]["checks"] = round(time.perf_counter() - t, 6)
    return mesh


def resolution_arguments(spacing: tuple, *, method: str, refine, max_size, subdivide,
                         coarsen, max_aspect=None) -> tuple[Lattice, float | None, int]:
    """Check the resolution options at the door: (lattice, max_size, coarsen level).

    Raises ValueError with what to pass for a refine level outside 0..4, a size cap below
    one lattice cell, a coarsening level outside 0..5, or a non-template method with any
    of them.
    """
    lattice = choose_lattice(spacing, refine=refine, subdivide=bool(subdivide),
                             max_aspect=max_aspect)
    max_size = check_max_size(max_size, lattice)
    coarsen = check_coarsen(coarsen)
    if method != "template" and (not lattice.is_voxel_lattice or max_size is not None):
        raise ValueError("the delaunay method meshes voxels as they are; use the template "
                         "method for refine, max_size or anisotropic subdivision (or "
                         "subdivide=False).")
    return lattice, max_size, coarsen


def check_periodic(method: str, periodic: bool) -> None:
    """Periodic faces come from the templates (cells of one lattice cell are always cut
    alike); ValueError for any other method."""
    if periodic and method != "template":
        raise ValueError("periodic meshes need the template method (the delaunay method "
                         "cannot match opposite faces).")


def warn_lost_materials(report: dict, names: dict | None = None) -> None:
    """Warn (naming them) about materials the coarsening removed entirely."""
    if report.get("lost"):
        lost = ", ".join(f"{m}" + (f" ({names[m]})" if names and m in names else "")
                         for m in report["lost"])
        warnings.warn(f"coarsening by 2^{report['level']} voxels removed material(s) {lost} "
                      "entirely: they are thinner than a block. Use a smaller --coarsen to "
                      "keep them.", UserWarning, stacklevel=3)


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
                 material_names: dict | None = None, lattice: Lattice | None = None,
                 max_size: float | None = None, periodic: bool = False
                 ) -> tuple[Mesh, RegionTree]:
    """The worker behind :func:`mesh_labels`; arguments come from :func:`_mesh_arguments`.

    Returns the mesh and the region tree it was cut from (in lattice cells), which the
    checks can reuse.
    """
    if lattice is None:
        lattice = Lattice(spacing, (1,) * len(spacing))
    t0 = time.perf_counter()
    if lattice.is_voxel_lattice and max_size is None and not periodic:
        tree = _build_tree(lab)
    else:
        tree = lattice_tree(lab, lattice, exclude=exclude, max_size=max_size,
                            periodic=periodic)
    seconds = {"tree": time.perf_counter() - t0}
    mesh = _mesh_tree(tree, method=method, exclude=exclude, spacing=lattice.step,
                      material_names=_names(material_names), connectivity=None,
                      report_face_balance=False, seconds=seconds, periodic=periodic)
    # the mesh describes the image it came from; the lattice is in info
    mesh.shape, mesh.spacing = tuple(lab.shape), tuple(spacing)
    mesh.info["spacing"] = list(spacing)
    mesh.info["shape"] = list(lab.shape)
    mesh.info["lattice"] = lattice.describe()
    if max_size is not None:
        mesh.info["max_size"] = max_size
    mesh.info["periodic"] = bool(periodic)
    return mesh, tree


def check_max_size(max_size, lattice: Lattice) -> float | None:
    """`max_size` as a float no smaller than one lattice cell's diagonal, or ValueError."""
    if max_size is None:
        return None
    try:
        value = float(max_size)
    except (TypeError, ValueError):
        value = float("nan")
    smallest = float(np.linalg.norm(lattice.step))
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"max_size must be a positive length; got {max_size!r}.")
    if value < smallest:
        raise ValueError(
            f"max_size {value:g} is below the longest edge of the smallest element "
            f"({smallest:.4g}: the diagonal of one lattice cell of size "
            f"{tuple(round(h, 6) for h in lattice.step)}); ask for at least {smallest:.4g}."
        )
    return value


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
               report_face_balance: bool, seconds: dict, periodic: bool = False) -> Mesh:
    """The worker behind :func:`mesh_tree` and :func:`mesh_labels`: trusted arguments;
    `seconds` holds the steps already timed (the tree) and receives the others.
    `periodic`: the tree's box faces are to be cut alike (the diagonal rule follows)."""
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
        # a periodic mesh needs the rule to survive the translation by the box size
        rule = "lowest" if periodic and any(n % 2 for n in tree.shape) else "parity"
        points, cells, leaf, template_id, vseconds, packed = template_mesh(bal, meshed,
                                                                          rule=rule)
        seconds.update(vseconds)
        t = time.perf_counter()
        table = template_quality(d, spacing)
        template_id = template_id.astype(np.intp)  # once, not once per look-up
        cell_data = {name: values[template_id] for name, values in table.items()}
        del template_id
        seconds["quality"] = time.perf_counter() - t
        info["n_plain_leaves"] = int(vseconds.pop("_n_plain"))
        seconds.pop("_n_plain", None)
        info["diagonal_rule"] = rule if d == 3 else "lowest"
    else:
        points, cells, leaf, cell_data, dinfo, vseconds = delaunay_mesh(bal, meshed)
        seconds.update(vseconds)
        info.update(dinfo)

    t = time.perf_counter()
    if any(s != 1.0 for s in spacing):
        points *= np.asarray(spacing)  # points is the mesher's own array: scale in place
    material = bal.label[leaf]
    cell_data = {"quality": cell_data.pop("quality"), "level": bal.level[leaf],
                 "leaf": leaf, **cell_data}
    mesh = Mesh._trusted(points, cells, material, cell_data, spacing=spacing,
                         shape=tuple(tree.shape), material_names=dict(material_names or {}),
                         info=info)
    if method == "template":
        # what the facet groups' pass would otherwise recompute from the points, valid
        # while the mesh's arrays are the ones made here
        mesh._made = MadeLattice.record(mesh, packed, bal.origin)
    seconds["assemble"] = time.perf_counter() - t

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
