"""Space resolution of a transient run: a mesh fine enough for the diffusion length, and
an estimate of the space error at the saved times.

**A priori: size from the diffusion length.** Near a fixed face or a jump of the initial
value the field at time ``t`` is close to the 1-D front ``erfc(x / 2L)``, ``L = sqrt(D t)``
(``D = k / c``). Its curvature at distance ``x`` is ``s exp(-s^2) / (sqrt(pi) L^2)``,
``s = x / 2L``; the largest over the saved times (``L`` from ``L1``, the earliest, to
``L_end``) is :func:`front_curvature`. P1's error is about ``CURVATURE_CONSTANT * h^2``
times the curvature, so an element of side ``h`` at distance ``x`` must have
``h <= sqrt(e / (CURVATURE_CONSTANT * curvature(x)))`` for an error ``e``: about
``L1 / 4`` at the source for 0.75 % of the jump, growing linearly with the distance
(``h ~ x / 8``) and without bound beyond a few ``L_end``. The label image is meshed with
a size cap, then the leaves still too large are split (the adaptive machinery of
:func:`~._adapt.refine_within`) until every element meets its size or the budget is
spent.

**A posteriori: the elliptic reconstruction.** At a saved time the P1 field ``u_h``
solves the steady problem ``K u_h = -M v`` for its own time derivative ``v``; the P2
solution ``w`` of the same problem on the same mesh (the load ``-M v`` in P2, the fixed
values held) is a better solution of it, and ``max |w - u_h|`` estimates the space error
(Makridakis and Nochetto's elliptic reconstruction; the hierarchical estimate of the
steady problem). It is tested against the 1-D analytic front.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from ..mesh import Mesh, mesh_labels
from ._adapt import refine_within
from ._assembly import fe_space, p1_embedding, stiffness_matrix
from ._fe import fe_basis, mass_basis, mass_matrix
from ._protocols import face_dofs
from ._solve import DirichletSolver, SPDSolver, connected_parts

__all__ = ["CURVATURE_CONSTANT", "ESTIMATE_UNKNOWNS", "SpaceEstimator", "front_curvature",
           "resolve_fronts"]

#: P1's max error per ``h^2 |u''|`` on the front (1/8 for interpolation; Galerkin with
#: the consistent mass measured up to about twice that on the erfc front).
CURVATURE_CONSTANT = 0.25
#: Most P2 unknowns the space estimate assembles (beyond: not estimated, and said so).
ESTIMATE_UNKNOWNS = 3_000_000
#: Most rounds of splitting for the size bound (each may go one lattice level finer).
SIZE_ROUNDS = 4
#: Most vertices the size bound may reach: this many times the voxel lattice's (a mesh
#: finer than the voxels where the front is, coarser elsewhere), and never more than the
#: P1 default's budget (issue 11).
VERTEX_FACTOR = 4.0
VERTEX_BUDGET = 3_000_000


def front_curvature(distance: np.ndarray, first: float, last: float) -> np.ndarray:
    """Largest ``|d^2/dx^2 erfc(x / 2L)|`` at `distance` for ``L`` in ``[first, last]``.

    At the source: the earliest front's largest curvature, ``exp(-1/2) / sqrt(2 pi)``.

    >>> round(float(front_curvature(np.array([0.0]), 1.0, 2.0)[0]), 3)
    0.242
    """
    x = np.asarray(distance, dtype=float)
    # s exp(-s^2) / L^2 in L at fixed x is largest at s^2 = 3/2
    length = np.clip(x / (2 * np.sqrt(1.5)), first, last)
    s = x / (2 * length)
    curve = s * np.exp(-s * s) / (np.sqrt(np.pi) * length ** 2)
    # near the source the largest curvature is the earliest front's, at s^2 = 1/2
    near = x <= np.sqrt(2.0) * first
    curve[near] = np.exp(-0.5) / np.sqrt(2 * np.pi) / first ** 2
    return curve


def _element_size(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(M,) side of each element's box (its leaf's side for template elements) and
    (M, d) centroid."""
    corners = mesh.points[mesh.cells]                               # (M, d+1, d)
    return np.ptp(corners, axis=1).max(axis=1), corners.mean(axis=1)


def source_distance(mesh: Mesh, centroids: np.ndarray, faces: list[str],
                    start_labels: np.ndarray | None, spacing) -> np.ndarray:
    """(M,) distance of each centroid to the nearest fixed face or jump of the initial
    value (`start_labels`: the initial value per voxel, or None for none)."""
    lo, hi = mesh.image_box()
    out = np.full(len(centroids), np.inf)
    d = mesh.ndim
    for face in faces:
        axis = d - 1 - "xyz".index(face[0])
        out = np.minimum(out, centroids[:, axis] - lo[axis] if face.endswith("min")
                         else hi[axis] - centroids[:, axis])
    if start_labels is not None:
        jump = np.zeros(start_labels.shape, dtype=bool)
        for axis in range(d):
            # NaN marks excluded voxels: no field there, so no jump against them
            a = np.take(start_labels, np.arange(start_labels.shape[axis] - 1), axis=axis)
            b = np.take(start_labels, np.arange(1, start_labels.shape[axis]), axis=axis)
            diff = (a != b) & np.isfinite(a) & np.isfinite(b)
            lead = [slice(None)] * d
            lead[axis] = slice(1, None)
            jump[tuple(lead)] |= diff
            lead[axis] = slice(None, -1)
            jump[tuple(lead)] |= diff
        if jump.any():
            spacing = np.asarray(spacing, dtype=float)
            # half a voxel: a jump voxel's centre is half a voxel from the interface
            dist = np.maximum(ndimage.distance_transform_edt(~jump, sampling=spacing)
                              - 0.5 * spacing.min(), 0.0)
            index = np.clip((centroids / spacing).astype(np.intp), 0,
                            np.asarray(start_labels.shape) - 1)
            out = np.minimum(out, dist[tuple(index.T)])
    return np.maximum(out, 0.0)


def vertex_budget(labels) -> float:
    """Most vertices a transient run's mesh of `labels` may have (:data:`VERTEX_FACTOR`
    times the voxel lattice's, at most :data:`VERTEX_BUDGET`)."""
    return min(VERTEX_BUDGET, VERTEX_FACTOR * float(np.prod(np.asarray(np.shape(labels))
                                                            + 1)))


def allowed_size(distance: np.ndarray, first: float, last: float, error: float
                 ) -> np.ndarray:
    """Largest element side at `distance` for a P1 error `error` (relative to the jump)."""
    with np.errstate(all="ignore"):      # far from every source the curvature is 0
        return np.sqrt(error / (CURVATURE_CONSTANT * front_curvature(distance, first, last)))


def resolve_fronts(labels, *, spacing, exclude, material_names, faces: list[str],
                   start_labels: np.ndarray | None, first: float, last: float,
                   error: float) -> tuple[Mesh, dict]:
    """The IMESH mesh of `labels`, its elements no larger than :func:`allowed_size`.

    Parameters
    ----------
    labels, spacing, exclude, material_names
        As for :func:`~napari_swa_imesh.mesh.mesh_labels`.
    faces : list of str
        Faces with a fixed value.
    start_labels : ndarray or None
        Initial value per voxel (None: uniform).
    first, last : float
        Shortest and longest diffusion length of the saved times (physical units).
    error : float
        Share of the error (relative to the jump) the mesh may take.

    Returns
    -------
    (Mesh, dict)
        The mesh and what was done: ``rounds``, ``max_ratio`` (largest element side over
        its allowance, <= 1 when met), ``met``, and the ``reason`` it was not.
    """
    if not faces and start_labels is None:          # nothing to resolve: the labels' mesh
        mesh = mesh_labels(labels, spacing=spacing, exclude=exclude,
                           material_names=dict(material_names or {}))
        return mesh, {"rounds": 0, "max_ratio": 0.0, "met": True,
                      "allowed_at_source": np.inf, "reason": "", "tree": None}
    spacing_arr = np.broadcast_to(np.asarray(1.0 if spacing is None else spacing,
                                             dtype=float), (np.ndim(labels),))
    smallest = float(allowed_size(np.zeros(1), first, last, error)[0])
    cap = smallest * 2 ** SIZE_ROUNDS
    extent = float(np.max(np.asarray(np.shape(labels)) * spacing_arr))
    # mesh_labels' cap is on a leaf's Kuhn diagonal: side times |step| / max(step)
    max_size = cap * float(np.linalg.norm(spacing_arr) / spacing_arr.max())
    if cap >= extent or max_size <= float(np.linalg.norm(spacing_arr)):
        max_size = None          # no cap, or none coarser than the voxels: the splits do it
    budget = vertex_budget(labels)
    mesh = mesh_labels(labels, spacing=spacing, exclude=exclude,
                       material_names=dict(material_names or {}), max_size=max_size)
    mesh, tree, rounds, ratio, reason = refine_to_sizes(
        labels, mesh,
        lambda m: _ratios(m, faces, start_labels, spacing_arr, first, last, error),
        budget, rounds_most=SIZE_ROUNDS, slack=0.0,
        budget_reason=f"the vertex budget of {int(budget)}, {VERTEX_FACTOR:g} times the "
                      "voxels'")
    worst = float(ratio.max(initial=0.0))
    return mesh, {"rounds": rounds, "max_ratio": worst, "met": worst <= 1.0 + 1e-9,
                  "allowed_at_source": smallest, "reason": reason, "tree": tree}


def refine_to_sizes(labels, mesh: Mesh, ratios: Callable[[Mesh], np.ndarray],
                    budget: float, *, rounds_most: int, slack: float, budget_reason: str
                    ) -> tuple[Mesh, object, int, np.ndarray, str]:
    """Split the leaves of elements larger than asked until none is.

    `ratios(mesh)` is each element's size over its allowance; leaves with a ratio above
    ``1 + slack`` are split (:func:`~._adapt.refine_within`, within `budget` vertices)
    until none is left, `rounds_most` rounds or the deepest refine level are reached,
    or a round adds no vertex or fills the budget (then `budget_reason` is the reason).

    Returns
    -------
    mesh, tree, rounds, ratio, reason
        The last mesh and its tree, the rounds taken, its ratios, why it stopped short
        (empty when every element meets its size).
    """
    from ._adapt import MAX_REFINE

    tree, rounds, reason = None, 0, ""
    ratio = ratios(mesh)
    while ratio.max(initial=0.0) > 1 + slack:
        if rounds >= rounds_most or _refine_level(mesh) >= MAX_REFINE:
            reason = f"{rounds} levels of splitting, the most"
            break
        leaf = np.asarray(mesh.cell_data["leaf"])
        per_leaf = np.zeros(int(leaf.max()) + 1)
        np.maximum.at(per_leaf, leaf, np.where(ratio > 1, ratio, 0.0))
        before = len(mesh.points)
        mesh, tree = refine_within(labels, mesh, per_leaf, budget, tree)
        rounds += 1
        ratio = ratios(mesh)
        if len(mesh.points) == before or len(mesh.points) > (1 - 0.05) * budget:
            reason = budget_reason
            break
    return mesh, tree, rounds, ratio, reason


def _ratios(mesh, faces, start_labels, spacing, first, last, error) -> np.ndarray:
    size, centroid = _element_size(mesh)
    # the element's nearest point to the source, not its centroid
    dist = np.maximum(source_distance(mesh, centroid, faces, start_labels, spacing)
                      - 0.5 * size, 0.0)
    return size / allowed_size(dist, first, last, error)


class SpaceEstimator:
    """P2 elliptic reconstruction of P1 fields on one mesh (assembled once).

    Parameters
    ----------
    mesh : Mesh
    tensors, cell_material, capacity_per_cell
        The conductivity per material, each element's material index and capacity.
    fixed : dict of str to float
        Fixed faces and values.
    tol : float
        Relative residual of the solves.
    """

    def __init__(self, mesh: Mesh, tensors, cell_material, capacity_per_cell,
                 fixed: dict, tol: float, mass1, stiffness1, free1: np.ndarray):
        # the P1 field's own time derivative: M v = -K u on the free dofs, so that u is
        # exactly the P1 solution of the steady problem reconstructed (a derivative from
        # the last two steps would carry their time error into the space estimate)
        self.free1 = free1
        self.stiff1 = stiffness1[free1].tocsr()
        self.mass1 = SPDSolver(mass1[free1][:, free1].tocsr(), tol=tol)
        space = fe_space(mesh, 2)
        self.edges = space.edges                           # (E, 2) vertices of P2's edges
        self.worst = None                                  # set by the caller
        self.embed = p1_embedding(space)                   # (n2, n1)
        stiffness = stiffness_matrix(space, tensors, cell_material)
        basis = fe_basis(mesh, 2)
        self.mass = mass_matrix(mass_basis(basis), capacity_per_cell)
        lo, hi = mesh.image_box()
        face_parts = [face_dofs(basis.doflocs, lo, hi, face) for face in fixed]
        self.fixed = np.concatenate(face_parts) if face_parts else np.zeros(0, dtype=np.intp)
        self.values = (np.concatenate([np.full(p.size, float(fixed[f]))
                                       for f, p in zip(fixed, face_parts)])
                       if face_parts else np.zeros(0))
        # a part touching no fixed value floats: pin one dof of it, and afterwards shift
        # the part so that its amount is the P1 field's (the reconstruction keeps it)
        parts = connected_parts(stiffness)
        anchored = np.zeros(int(parts.max()) + 1, dtype=bool)
        anchored[parts[self.fixed]] = True
        first = np.unique(parts, return_index=True)[1]
        self.pins = first[~anchored[parts[first]]]
        self.parts = parts
        self.floating = ~anchored[parts]
        self.solver = DirichletSolver(stiffness, np.concatenate([self.fixed, self.pins]),
                                      tol=tol, coarse=self.embed)

    @property
    def unknowns(self) -> int:
        return int(self.mass.shape[0])

    def error(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        """``max |w - u|`` and the (n2,) difference, for the P1 field `u`."""
        rate = np.zeros_like(u)
        rate[self.free1] = self.mass1.solve(-(self.stiff1 @ u))[0]
        u2 = self.embed @ u
        load = -(self.mass @ (self.embed @ rate))
        w, _ = self.solver.solve(np.concatenate([self.values, u2[self.pins]]), load,
                                 x0=u2)
        if self.pins.size:
            size = len(self.parts)
            per_dof = self.mass @ (w - u2)            # int c (w - u2) phi_i
            weight = self.mass @ np.ones(size)        # int c phi_i
            excess = np.bincount(self.parts, per_dof, minlength=int(self.parts.max()) + 1)
            capacity = np.bincount(self.parts, weight, minlength=int(self.parts.max()) + 1)
            shift = np.where(self.floating, excess[self.parts] / capacity[self.parts], 0.0)
            w = w - shift
        diff = w - u2
        return float(np.abs(diff).max(initial=0.0)), diff


def _refine_level(mesh: Mesh) -> int:
    """Interface refinement level K of the lattice `mesh` was made on (0 if unrecorded)."""
    lattice = None if mesh.recipe is None else mesh.recipe.lattice
    return 0 if lattice is None else int(lattice.refine)
