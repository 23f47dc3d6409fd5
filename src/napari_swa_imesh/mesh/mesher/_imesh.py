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
from collections.abc import Generator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..._region_tree import RegionTree, _build_tree
from ..._steps import run_steps
from ..._validation import normalize_spacing
from ..checks._checks import _check_mesh
from ..model._recipe import MadeLattice, Recipe
from ..model._types import Mesh
from ..model._world import world_from_affine
from ._balance import balance_tree, count_balanced_leaves
from ._coarsen import coarsen_labels
from ._delaunay import delaunay_mesh
from ._door import (  # noqa: F401
    METHODS,
    _exclude_array,
    _mesh_arguments,
    check_max_size,
    check_periodic,
    record_coarsening,
    resolution_arguments,
    warn_lost_materials,
)
from ._lattice import Lattice, lattice_tree
from ._templates import template_mesh, template_quality

__all__ = ["mesh_labels", "mesh_tree", "plan_mesh", "MeshPlan", "Meshed"]



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
        ``level`` and ``leaf`` (index of the balanced leaf), and
        ``min_angle``/``max_angle`` (2-D) or ``min_dihedral``/``max_dihedral`` (3-D) in
        degrees; ``recipe`` says how it was made (:class:`~._recipe.Recipe`: method,
        exclusions, lattice, size cap, periodic faces, coarsening); ``info`` holds counts,
        the worst ratio, the angle range and seconds per step.

    Notes
    -----
    The mesher works on the lattice of :func:`choose_lattice` (``recipe.lattice``): the
    voxels themselves for cubic spacing without refinement. The per-element metrics are
    those of the physical elements; ``level`` counts lattice cells. Template elements per
    leaf, when no edge midpoint or face centre of the leaf is a vertex: 2 in 2-D, 5 in 3-D
    (6, Kuhn's, in a periodic mesh with an odd extent: ``recipe.diagonal_rule``); else
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
    return plan_mesh(labels, method=method, exclude=exclude, spacing=spacing,
                     material_names=material_names, affine=affine, refine=refine,
                     max_size=max_size, subdivide=subdivide, coarsen=coarsen,
                     periodic=periodic, max_aspect=max_aspect).run().mesh


class Meshed(NamedTuple):
    """What :meth:`MeshPlan.steps` returns: the mesh, the region tree it was cut from (in
    lattice cells; the checks reuse it) and the labels meshed (coarsened when asked)."""

    mesh: Mesh
    tree: RegionTree
    labels: np.ndarray


@dataclass
class MeshPlan:
    """A meshing run checked at the door (:func:`plan_mesh`), to run step by step, once.

    The command line, the napari Mesh tab and the batch pipeline (through
    :func:`mesh_labels`) drive this one plan: what it knows before meshing (the lattice,
    for a memory estimate; the labels, for a format's limits) is here, and
    :meth:`steps` does the rest. Running lets go of `labels` (None after), so coarsened
    labels do not keep the full-size ones alive while they are meshed.
    """

    labels: np.ndarray               # the door's labels: dtype kept, no copy
    method: str
    exclude: np.ndarray              # sorted unique int64
    spacing: tuple[float, ...]
    world: np.ndarray | None
    lattice: Lattice
    max_size: float | None
    coarsen: int
    periodic: bool
    material_names: dict[int, str]

    def steps(self, *, report_checks: bool = True
              ) -> Generator[tuple[int, int, str], None, Meshed]:
        """Coarsen (when asked), mesh, then (Delaunay, with `report_checks`) check, as
        (done, total, message) progress; returns :class:`Meshed`."""
        if self.labels is None:
            raise ValueError("this plan has run already; make another with plan_mesh.")
        checks = report_checks and self.method == "delaunay"
        total = 1 + bool(self.coarsen) + checks
        lab, self.labels = self.labels, None
        if self.coarsen:
            yield 0, total, f"coarsening the labels to blocks of {2 ** self.coarsen} voxels"
        lab, report = coarsen_labels(lab, self.coarsen, self.exclude)
        yield int(bool(self.coarsen)), total, f"{self.method} mesh of the balanced 2^d-tree"
        mesh, tree = _mesh_labels(lab, method=self.method, exclude=self.exclude,
                                  spacing=self.spacing, material_names=self.material_names,
                                  lattice=self.lattice, max_size=self.max_size,
                                  periodic=self.periodic)
        mesh.world = self.world
        if self.coarsen:
            record_coarsening(mesh, report)
        if checks:  # report the reference's step as it is
            yield total - 1, total, "checking the mesh"
            t = time.perf_counter()
            found = _check_mesh(mesh, lab, self.exclude, tree)
            mesh.info["checks"] = found.to_dict()
            mesh.info["conforming"] = found.conforming
            mesh.info["seconds"]["checks"] = round(time.perf_counter() - t, 6)
        return Meshed(mesh, tree, lab)

    def run(self, **options) -> Meshed:
        """:meth:`steps` to the end."""
        return run_steps(self.steps(**options))


def plan_mesh(labels, *, method: str = "template", exclude=(), spacing=None,
              material_names: dict[int, str] | None = None, affine=None, refine: int = 0,
              max_size: float | None = None, subdivide: bool = True, coarsen: int = 0,
              periodic: bool = False, max_aspect: float | None = None,
              name: str = "labels") -> MeshPlan:
    """Check the arguments of :func:`mesh_labels` (same parameters; `name` is how errors
    call the labels) and return the :class:`MeshPlan` that meshes them.

    Examples
    --------
    >>> plan = plan_mesh(np.array([[1, 1], [1, 2]]), spacing=(2.0, 1.0))
    >>> plan.lattice.factors, plan.run().mesh.n_cells
    ((2, 1), 13)
    """
    lab, spacing_t, exclude_arr = _mesh_arguments(labels, method=method, exclude=exclude,
                                                   spacing=spacing, name=name)
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
    return MeshPlan(lab, method, exclude_arr, spacing_t, world, lattice, max_size, coarsen,
                    bool(periodic), _names(material_names))


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
    # the mesh describes the image it came from; the lattice is in its recipe
    mesh = _mesh_tree(tree, method=method, exclude=exclude, spacing=lattice.step,
                      material_names=_names(material_names), connectivity=None,
                      report_face_balance=False, seconds=seconds, periodic=periodic,
                      image=(tuple(lab.shape), tuple(spacing)), lattice=lattice,
                      max_size=max_size)
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
        raise ValueError("templates need balance across faces and edges "
                         f"(connectivity >= {d - 1}).")
    return _mesh_tree(tree, method=method, exclude=_exclude_array(exclude),
                      spacing=normalize_spacing(spacing, d), material_names=_names(material_names),
                      connectivity=connectivity, report_face_balance=bool(report_face_balance),
                      seconds={})


def _mesh_tree(tree: RegionTree, *, method: str, exclude: np.ndarray, spacing: tuple,
               material_names: dict[int, str], connectivity: int | None,
               report_face_balance: bool, seconds: dict, periodic: bool = False,
               image: tuple[tuple, tuple] | None = None, lattice: Lattice | None = None,
               max_size: float | None = None, adapted=None) -> Mesh:
    """The worker behind :func:`mesh_tree` and :func:`mesh_labels`: trusted arguments;
    `seconds` holds the steps already timed (the tree) and receives the others.
    `periodic`: the tree's box faces are to be cut alike (the diagonal rule follows).
    `image`: the (shape, voxel spacing) of the label image the tree is the lattice of
    (default: the tree's own shape and `spacing`); `lattice`, `max_size` and `adapted`
    go into the recipe as they are."""
    d = tree.ndim
    if connectivity is None:
        connectivity = 1 if method == "delaunay" else max(1, d - 1)

    t = time.perf_counter()
    bal = balance_tree(tree, connectivity=connectivity)
    seconds["balance"] = time.perf_counter() - t
    meshed = bal.inside & ~np.isin(bal.label, exclude)
    info = {
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
        points, cells, leaf, template_id, vseconds, packed, n_plain = template_mesh(
            bal, meshed, rule=rule)
        seconds.update(vseconds)
        t = time.perf_counter()
        table = template_quality(d, spacing)
        template_id = template_id.astype(np.intp)  # once, not once per look-up
        cell_data = {name: values[template_id] for name, values in table.items()}
        del template_id
        seconds["quality"] = time.perf_counter() - t
        info["n_plain_leaves"] = n_plain
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
    shape, voxel = image if image is not None else (tuple(tree.shape), spacing)
    mesh = Mesh._trusted(points, cells, material, cell_data, spacing=tuple(voxel),
                         shape=tuple(shape), material_names=dict(material_names or {}),
                         info=info)
    mesh.recipe = Recipe(
        method=method, exclude=tuple(exclude.tolist()),
        balance={1: "faces", 2: "faces+edges", 3: "faces+edges+corners"}.get(
            connectivity, f"connectivity {connectivity}"),
        lattice=lattice, max_size=max_size, periodic=bool(periodic),
        diagonal_rule=(rule if d == 3 else "lowest") if method == "template" else None,
        adapted=adapted)
    if method == "template":
        # what the facet groups' pass would otherwise recompute from the points, valid
        # while the mesh holds the (now read-only) arrays made here
        mesh.made = MadeLattice.record(mesh, packed, bal.origin)
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
