"""Default accuracy: which elements, and where to refine, chosen from a first solve.

On label images at contrast 100 the error of k_eff comes from the corners and edges of
the voxel staircase, where the flux is singular; refining every interface (``refine``)
pays for flat interfaces too. The default (``order="auto"``, ``adapt="auto"``) instead:

1. solves P1 on the IMESH mesh (cheap: about an eighth of the P2 unknowns in 3-D);
2. computes the flux-jump indicator of every element (the jump of the normal flux
   across its facets, squared, times the facet measure and size; summed over the axes
   solved, each axis normalised to weigh the same) and marks the fewest elements that
   carry ``THETA`` of its total (Doerfler marking);
3. meshes the labels again one lattice level finer in the marked cells
   (:func:`~napari_swa_imesh.mesh.mesher._adapt.refine_marked`) and solves P2 there.

P1 asked with ``adapt="auto"`` takes :data:`P1_STEPS` steps instead, each splitting the
leaves of largest indicator, as many as keep the vertices within their share of
:data:`P1_GROWTH` times the labels' voxel-lattice mesh's (:func:`refine_within`,
:func:`voxel_lattice_vertices`; for cubic voxels that is the first mesh). The budget is
the image's, not the first mesh's: anisotropic voxels are cut into cells for the quality
bound (2 x 2 x 3 at 1 / 0.8 / 1.2), which already refines every interface, and a budget
relative to that mesh bought 4.9 x 2.9 times the isotropic unknowns (1.4 GB on a
40 x 50 x 30 image). Counted from the image, that case takes 239k unknowns and 0.54 GB and
is +2.0 / +2.2 / +2.3 % (x / y / z) above P2 on the same mesh, as the same labels on cubic
voxels are above their P2 default (+2.0 / +1.9 / +2.3 %): the same accuracy for the same
image. On these images the
error of P1 falls with the vertices at the same rate whatever theta or facet weighting
marks them (about N^-0.5, measured on 32^3 blobs), so the budget, not theta, is what
decides the accuracy, and a budget is what a user can plan for.

Measured by ``benchmarks/bench_simulate.py``: on 32^3 three-phase blobs (contrast 100)
the error against the extrapolated voxel reference drops from 4.7 % (P1) and 1.2 % (P2)
to 0.87 % with 1.65 times the P2 unknowns; uniform interface refinement of P2 needs 6.7
times them for 0.46 %. When the P2 unknowns would pass ``P2_BUDGET`` (about 3 GB of
assembly and multigrid), the default falls back to P2 without adapting, then to P1, and
says so.
"""

from __future__ import annotations

import numpy as np

from ..mesh.mesher._adapt import _refine_marked
from ..mesh.checks._facets import paired_facets
from ..mesh.mesher._lattice import MAX_REFINE
from ..mesh.model._quality import signed_volumes
from ..mesh.model._types import Mesh

__all__ = ["AUTO", "P1_GROWTH", "P1_STEPS", "P2_BUDGET", "THETA", "auto_settings", "doerfler",
           "flux_jump_indicator", "refine_within", "voxel_lattice_vertices"]

AUTO = "auto"
#: Doerfler fraction of the indicator to refine (0.4 measured best per unknown of 0.2-0.5).
THETA = 0.4
#: Most P2 unknowns the default takes on (measured 1.3 kB per unknown at 64^3).
P2_BUDGET = 3_000_000
#: P2 unknowns per vertex on IMESH meshes (vertices + edges; measured 7.55 in 3-D, 3.9
#: in 2-D), and the growth of one adaptive step (measured 1.65, rounded up).
P2_PER_VERTEX = {2: 4.0, 3: 7.7}
ADAPT_GROWTH = 1.8
#: P1's default adaptive steps and the growth of its vertices they may reach together
#: (issue 11's budget is at most 3x the vertices, 600k at 64^3 where the first mesh has
#: 202k: the fitted count lands within BUDGET_SLACK under this), and the most vertices
#: it adapts to.
P1_STEPS = 2
P1_GROWTH = 2.9
P1_BUDGET = 3_000_000
#: First guess of the vertices one split leaf adds (measured 19-27 on blobs), and how
#: many meshes a budgeted step may try; it keeps the largest within budget.
VERTICES_PER_SPLIT = 24.0
BUDGET_TRIES = 6
BUDGET_SLACK = 0.05   # a try within 5 % under the budget is good enough
#: Least growth of the vertices worth the default's adaptive steps (each costs a P1 solve
#: and a mesh; 20 % more vertices lower P1's error by under 9 % at N^-0.5).
P1_MIN_GROWTH = 1.2
TIE = 1e-9  # relative: indicators this close are one value
#: Indicator total (relative to the flux energy, so scale-free) below which the field is
#: exact up to round-off (measured 1e-25 on laminates, 1e-3 and more on real images).
FLOOR = 1e-12
#: Facets per chunk of the indicator's geometry (about 30 MB of temporaries in 3-D).
INDICATOR_CHUNK = 1 << 18


def auto_settings(mesh: Mesh, order, adapt, from_labels: bool,
                  reference: int | None = None) -> tuple[int, int, float | None, str]:
    """Resolve ``"auto"`` order and adaptive steps for `mesh`.

    `reference` is the vertex count of the labels meshed on voxel cells
    (:func:`voxel_lattice_vertices`; None: `mesh`'s own, right for a voxel lattice): the
    P1 default's budget is :data:`P1_GROWTH` times it.

    Returns (order, adapt, growth, why): `growth` is the vertex budget of the adaptive
    steps together (relative to `mesh`), None for Doerfler marking with :data:`THETA`.

    Raises ValueError for adaptive steps asked of a mesh that cannot take them (no labels,
    coarsened, or past the finest refine level).
    """
    p2 = P2_PER_VERTEX[mesh.ndim] * len(mesh.points)
    room = MAX_REFINE - int(mesh.info.get("lattice", {}).get("refine", MAX_REFINE))
    can_adapt = (from_labels and mesh.info.get("method") == "template"
                 and not mesh.info.get("coarsen"))
    # periodic faces must match, so a finer lattice refines whole box faces: the default
    # does not adapt there (its cost is not the growth the budget counts)
    auto_adapts = can_adapt and not mesh.info.get("periodic")
    fits_adapted = auto_adapts and room > 0 and p2 * ADAPT_GROWTH <= P2_BUDGET
    note, growth, asked_p1 = "", None, order == 1
    if order == AUTO:
        order = 2 if p2 <= P2_BUDGET else 1
        why = f"P{order}"
        if order == 1:
            note = (f"P2 would need about {p2:,.0f} unknowns, above the default's budget of "
                    f"{P2_BUDGET:,}; pass order 2 to insist")
    else:
        why = f"P{order} (asked)"
    if adapt == AUTO:
        if order == 2:
            # the adaptive step belongs to P2's default, within the same budget
            adapt = 1 if fits_adapted else 0
            if auto_adapts and room > 0 and not fits_adapted:
                note = f"not adapted: it would pass the default's budget of {P2_BUDGET:,} unknowns"
        elif asked_p1 and auto_adapts and room > 0:
            # P1 asked: budgeted steps (the P1 the default falls back to is too big already)
            start = len(mesh.points)
            base = start if reference is None else int(reference)
            fits = base * P1_GROWTH <= P1_BUDGET
            gain = base * P1_GROWTH / start
            if not fits:
                adapt = 0
                note = (f"not adapted: {P1_GROWTH:g}x the vertices would pass the P1 "
                        f"budget of {P1_BUDGET:,} unknowns")
            elif gain < P1_MIN_GROWTH:
                adapt = 0
                note = (f"not adapted: the mesh has {start:,} vertices (its voxels cut for "
                        f"the spacing), under {P1_MIN_GROWTH:g}x short of the budget, "
                        f"{P1_GROWTH:g}x the {base:,} of the labels on voxel cells")
            else:
                adapt, growth = min(P1_STEPS, room), gain
        else:
            adapt = 0
    if adapt and not can_adapt:
        raise ValueError("adaptive refinement needs a label image to mesh again (a mesh "
                         "read from a file or coarsened cannot be refined): pass adapt=0, "
                         "or simulate the labels.")
    if adapt > room:
        raise ValueError(f"{adapt} adaptive step{'s' * (adapt > 1)} would pass the finest "
                         f"refine level {MAX_REFINE} (the mesh is at "
                         f"{MAX_REFINE - room}): lower refine or adapt.")
    if adapt:
        why += f", {adapt} adaptive step" + "s" * (adapt > 1)
        if growth is not None:
            why += f" within {growth:.3g}x the vertices"
    return order, int(adapt), growth, why + (f" ({note})" if note else "")


def voxel_lattice_vertices(labels, mesh: Mesh) -> int:
    """Vertices of `labels` meshed as `mesh` was but on voxel cells (no subdivision for
    the spacing, the same interface refinement): the image's own size, which the P1
    default's budget counts from.

    Equal to ``len(mesh.points)`` for a mesh on the voxel lattice (returned without
    meshing). Otherwise the labels are meshed once more on the coarser lattice (a
    fraction of the first mesh's cost; vertex counts do not depend on the cell shape).
    The refine level asked is read from the lattice: the subdivision's ``j`` levels
    (every axis cut into at least ``2**j``) count toward it, so a lattice at refine
    ``r > 0`` was asked ``r + j``, and one at 0 is taken as asked 0.
    """
    from ..mesh.mesher._imesh import _mesh_arguments, _mesh_labels
    from ..mesh.mesher._lattice import Lattice

    described = mesh.info["lattice"]
    factors = tuple(int(f) for f in described["factors"])
    if all(f == 1 for f in factors):
        return len(mesh.points)
    refine = int(described["refine"])
    if refine:
        refine += min(factors).bit_length() - 1
    spacing = tuple(float(s) for s in mesh.info["spacing"])
    lab, _, exclude = _mesh_arguments(labels, method="template", exclude=mesh.info["exclude"],
                                      spacing=spacing)
    plain = Lattice(spacing, (1,) * len(spacing), min(refine, MAX_REFINE), None)
    voxel, _ = _mesh_labels(lab, method="template", exclude=exclude, spacing=spacing,
                            lattice=plain, max_size=mesh.info.get("max_size"),
                            periodic=bool(mesh.info.get("periodic")))
    return len(voxel.points)


def check_adapt(adapt) -> int | str:
    """`adapt` as ``"auto"`` or an int in 0..2, or ValueError saying what to pass."""
    if adapt == AUTO:
        return AUTO
    if isinstance(adapt, bool) or not isinstance(adapt, (int, np.integer)) or not 0 <= adapt <= 2:
        raise ValueError(f"adapt must be 'auto' or 0, 1 or 2 adaptive steps, not {adapt!r}.")
    return int(adapt)


def flux_jump_indicator(mesh: Mesh, fluxes) -> np.ndarray:
    """Per element: the jumps of the normal flux across its interior facets.

    Parameters
    ----------
    mesh : Mesh
    fluxes : iterable of (M, d) ndarray
        Element fluxes (x, y(, z) components) of the solves to weigh, each relative to
        its flux energy ``sum |q|^2 |T|``.

    Returns
    -------
    (M,) ndarray of float
        ``sum over facets F of the element of h_F |F| [q . n]^2``, ``h_F = |F|^(1/(d-1))``.
    """
    d = mesh.ndim
    facets, owners, _ = paired_facets(mesh.cells)
    inner = np.flatnonzero(owners[:, 1] >= 0)
    a, b = owners[inner, 0], owners[inner, 1]
    del owners
    # per-facet geometry and jumps a chunk of facets at a time: gathering the corners of
    # every facet at once (G, d, d) and its temporaries was the peak of an adaptive step
    # (0.76 GB for 1.2M tetrahedra); the values are the same, element by element
    n = len(inner)
    weight, normal = np.empty(n), np.empty((n, d))
    for lo in range(0, n, INDICATOR_CHUNK):
        part = slice(lo, min(n, lo + INDICATOR_CHUNK))
        p = mesh.points[facets[inner[part]]]
        if d == 2:
            edge = p[:, 1] - p[:, 0]
            measure = np.linalg.norm(edge, axis=1)
            normal[part] = np.stack([edge[:, 1], -edge[:, 0]], axis=1) / measure[:, None]
        else:
            cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            measure = 0.5 * np.linalg.norm(cross, axis=1)
            normal[part] = cross / (2 * measure)[:, None]
        weight[part] = measure ** (1.0 / (d - 1)) * measure
    del facets, inner
    volume = signed_volumes(mesh.points, mesh.cells)    # positive: the mesh's orientation
    total = np.zeros(mesh.n_cells)
    jump = np.empty(n)
    for q in fluxes:
        q = np.asarray(q, dtype=float)[:, ::-1]  # x, y(, z) -> the points' array order
        for lo in range(0, n, INDICATOR_CHUNK):
            part = slice(lo, min(n, lo + INDICATOR_CHUNK))
            jump[part] = np.einsum("ij,ij->i", q[a[part]] - q[b[part]], normal[part])
        # relative to the solve's own flux energy (same units): axes weigh the same, and
        # an exact field (round-off jumps) stays at round-off
        energy = float(np.sum(volume * np.einsum("ij,ij->i", q, q)))
        if energy > 0:
            e = weight * jump ** 2 / energy
            total += np.bincount(a, e, mesh.n_cells) + np.bincount(b, e, mesh.n_cells)
    return total


def doerfler(indicator: np.ndarray, theta: float = THETA) -> np.ndarray:
    """The fewest elements whose indicator sums to `theta` of the total, and any others
    equal to the smallest of them (bool mask)."""
    indicator = np.asarray(indicator, dtype=float)
    total = indicator.sum()
    if total <= FLOOR:        # an exact field: its jumps are round-off, nothing to refine
        return np.zeros(indicator.shape, dtype=bool)
    ranked = np.sort(indicator)[::-1]
    running = np.cumsum(ranked)      # its last entry is the total, in the same rounding
    count = min(len(ranked), int(np.searchsorted(running, theta * running[-1])) + 1)
    return _largest(indicator, ranked, count)


def _largest(values: np.ndarray, ranked: np.ndarray, count: int) -> np.ndarray:
    """The `count` largest `values` (`ranked`: sorted descending) and any equal to the
    last of them up to :data:`TIE`: ties (mirror-image elements, equal up to rounding) are
    marked together, so a transposed image is refined the same way."""
    return values >= ranked[count - 1] * (1 - TIE)


def refine_within(labels, mesh: Mesh, leaf_indicator: np.ndarray, target: float, tree=None):
    """The labels meshed again with the leaves of largest indicator split, as many as keep
    the vertices within `target`.

    Parameters
    ----------
    labels : array_like of int
        The label image `mesh` was made from.
    mesh : Mesh
        A template mesh of `labels` (or the last adaptive step's).
    leaf_indicator : (L,) ndarray
        Indicator per balanced leaf (``bincount`` of the elements' over their ``leaf``).
    target : float
        Most vertices the new mesh may have.
    tree : RegionTree, optional
        The tree the last adaptive step returned (required after one).

    Returns
    -------
    (Mesh, RegionTree)
        The largest mesh tried within `target` (the vertices a split adds depend on its
        neighbours' balance, so the count is fitted from each try), and its tree. With
        no room for one split, or an exact field, nothing is split (the lattice is still
        one level finer, so the steps stay counted).
    """
    leaf = np.asarray(mesh.cell_data["leaf"])
    values = np.asarray(leaf_indicator, dtype=float)
    ranked = np.sort(values)[::-1]
    useful = int(np.count_nonzero(ranked > 0)) if values.sum() > FLOOR else 0
    vertices = len(mesh.points)
    best, count = None, int(min(useful, (target - vertices) // VERTICES_PER_SPLIT))
    for _ in range(BUDGET_TRIES):
        if count < 1:
            break
        split = _largest(values, ranked, count)
        out = _refine_marked(labels, mesh, split[leaf], tree)
        reached = len(out[0].points)
        if reached <= target:
            best = out if best is None or reached > len(best[0].points) else best
            if reached >= (1 - BUDGET_SLACK) * target or count == useful:
                break
        out = None       # a try not kept must not stay alive while the next one is made
        # scattered splits cost more each (their balance), so aim a little under
        again = int(min(useful, count * (target - vertices) / max(reached - vertices, 1)
                        * (1 - BUDGET_SLACK / 2)))
        if again == count:
            again -= 1 if reached > target else 0
            if again == count:
                break
        count = again
    if best is None:
        best = _refine_marked(labels, mesh, np.zeros(mesh.n_cells, dtype=bool), tree)
    return best
