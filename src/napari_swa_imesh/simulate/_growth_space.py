"""Space resolution of a reaction-diffusion run: elements no larger than the front needs.

A Fisher-KPP front travels with the speed ``2 sqrt(D rho)`` and keeps the width
``w = sqrt(D / rho)`` (the wave ``c(x - s t)`` falls from 0.9 to 0.1 over about 4.4 w);
a drug penetrates a tissue over ``w = sqrt(D / lambda)``. P1 elements of side ``w / n``
resolve it (n = :data:`FRONT_CELLS`: the wave speed within 1 % on the 1-D slab, tested),
so every element of a material that the front can reach in the run gets that bound: the
ball around the seed of radius ``r + s_max T`` plus a few widths (Fisher-KPP), the whole
tissue (drug). The label image is meshed with the coarsest bound as the size cap, then the
leaves still too large are split by the adaptive machinery (:func:`~._adapt.refine_within`)
until they meet it or the vertex budget is spent, which is said.
"""

from __future__ import annotations

import numpy as np

from ..mesh import Mesh, mesh_labels
from ._transient_space import VERTEX_BUDGET, _element_size, refine_to_sizes, vertex_budget

__all__ = ["FRONT_CELLS", "bound_sizes", "front_mesh", "size_ratio"]

#: Elements per front width ``sqrt(D / rho)`` (or ``sqrt(D / lambda)``).
FRONT_CELLS = 4.0
#: Most rounds of splitting below the cap (each one level finer).
SIZE_ROUNDS = 6
#: Widths beyond the front's farthest reach that are still resolved.
REACH_MARGIN = 6.0
#: Fewest vertices the splitting may reach (a small image's budget, 4 times its voxel
#: lattice, is too few for a front narrower than a voxel).
VERTEX_FLOOR = 50_000


def bound_sizes(widths: dict[int, float], cells: float) -> dict[int, float]:
    """Largest element side per material: its front width over `cells`."""
    return {m: (w / cells if w > 0 else np.inf) for m, w in widths.items()}


def size_ratio(mesh: Mesh, sizes: dict[int, float], reach: tuple[np.ndarray, float] | None
               ) -> np.ndarray:
    """(M,) each element's side over its bound (0 outside the reach: not bounded).

    Parameters
    ----------
    mesh : Mesh
    sizes : dict of int to float
        Bound per material.
    reach : (centre, radius) or None
        The ball (mesh coordinates) the front can reach; None: everywhere.
    """
    side, centroid = _element_size(mesh)
    table = np.array([sizes.get(int(m), np.inf) for m in mesh.material], dtype=float)
    ratio = side / table
    if reach is not None:
        centre, radius = reach
        near = np.linalg.norm(centroid - centre, axis=1) - side <= radius
        ratio = np.where(near, ratio, 0.0)
    return ratio


def front_mesh(labels, *, spacing, exclude, material_names, sizes: dict[int, float],
               reach: tuple[np.ndarray, float] | None) -> tuple[Mesh, dict]:
    """The IMESH mesh of `labels` with the elements the front can reach within `sizes`.

    Parameters
    ----------
    labels, spacing, exclude, material_names
        As for :func:`~napari_swa_imesh.mesh.mesh_labels`.
    sizes : dict of int to float
        Largest element side per material (physical units; inf: unbounded).
    reach : (centre, radius) or None
        As for :func:`size_ratio`.

    Returns
    -------
    (Mesh, dict)
        The mesh and what was done: ``rounds`` of splitting, ``max_ratio`` (largest
        side over its bound, <= 1 when met), ``met`` and the ``reason`` it was not.
    """
    spacing_arr = np.broadcast_to(np.asarray(1.0 if spacing is None else spacing,
                                             dtype=float), (np.ndim(labels),))
    finite = [s for s in sizes.values() if np.isfinite(s)]
    max_size = None
    if finite:
        cap = max(finite)
        # mesh_labels' cap is on a leaf's Kuhn diagonal: side times |step| / max(step)
        max_size = cap * float(np.linalg.norm(spacing_arr) / spacing_arr.max())
        # finer than the voxels: the voxels, then the splits do the rest
        max_size = max(max_size, float(np.linalg.norm(spacing_arr)) * (1 + 1e-9))
    mesh = mesh_labels(labels, spacing=spacing, exclude=exclude,
                       material_names=dict(material_names or {}), max_size=max_size)
    budget = min(VERTEX_BUDGET, max(vertex_budget(labels), VERTEX_FLOOR))
    mesh, _, rounds, ratio, reason = refine_to_sizes(
        labels, mesh, lambda m: size_ratio(m, sizes, reach), budget,
        rounds_most=SIZE_ROUNDS, slack=1e-9,
        budget_reason=f"the vertex budget of {int(budget)} vertices")
    worst = float(ratio.max(initial=0.0))
    return mesh, {"rounds": rounds, "max_ratio": worst, "met": worst <= 1 + 1e-9,
                  "reason": reason}
