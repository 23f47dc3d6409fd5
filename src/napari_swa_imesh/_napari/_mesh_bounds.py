"""The quality bound shown with a mesh: its range for the mesh's voxels, and its words.

Plain helpers of the Mesh tab (no Qt): the shaded band of the histogram, the canvas
legend and the summary's sentence all say the same bound, taken from
:func:`napari_swa_imesh.mesh.quality_bounds` for the lattice the mesh was cut on.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

from ..mesh import quality_bounds

if TYPE_CHECKING:
    from ..mesh import Mesh

__all__ = ["bound_range", "bound_label", "quality_legend"]


@cache
def bound_range(ndim: int, spacing: tuple[float, ...] = (), subdivide: bool = True,
                max_aspect: float | None = None) -> tuple[float, float]:
    """Radius-to-edge range of every IMESH template element for these voxels (shaded).

    From the regular simplex (the best any element can be) to the worst template simplex
    stretched by the lattice cells the mesher cuts voxels of `spacing` into
    (:func:`napari_swa_imesh.mesh.quality_bounds`; the voxels themselves with
    ``subdivide=False``; cells of residual aspect at most `max_aspect`): for cubic cells
    the proven bound of :func:`~napari_swa_imesh.mesh.quality_table`, which meshes every
    leaf configuration with the mesher's own templates, not a number copied here. About
    1.5 s in 3-D the first time, so call it in a worker first; it is cached.
    """
    return quality_bounds(ndim, spacing or None, subdivide=subdivide,
                          max_aspect=max_aspect if subdivide else None)["quality"]


def _mesh_bound(mesh: Mesh) -> tuple[float, float]:
    """:func:`bound_range` for the lattice `mesh` was cut on (its recorded max aspect)."""
    subdivided = _subdivided(mesh)
    return bound_range(mesh.ndim, mesh.spacing, subdivided,
                       mesh.recipe.lattice.max_aspect if subdivided else None)


def _subdivided(mesh: Mesh) -> bool:
    """Whether the mesh was cut on a lattice finer than its voxels for anisotropy."""
    return mesh.recipe is not None and mesh.recipe.subdivided


def _method(mesh: Mesh) -> str:
    """The method that made `mesh` (the template mesher's when it does not say)."""
    return "template" if mesh.recipe is None else mesh.recipe.method


def _aspect(spacing: tuple[float, ...]) -> str:
    """Voxel proportions as text: (2.0, 1.0, 1.0) -> "2:1:1"."""
    smallest = min(spacing)
    return ":".join(f"{s / smallest:.3g}" for s in spacing)


def bound_label(mesh: Mesh) -> str:
    """What the shaded range is for `mesh`: the IMESH bound for its voxels, or none."""
    cubic = len(set(mesh.spacing)) <= 1
    voxels = "square/cubic voxels" if cubic else f"{_aspect(mesh.spacing)} voxels"
    if _subdivided(mesh):
        voxels += " in " + " x ".join(str(f) for f in mesh.recipe.lattice.factors) + " cells"
    if _method(mesh) != "template":
        return f"template bound, {voxels} ({_method(mesh)} proves none)"
    return f"IMESH bound, {voxels}"


def quality_legend(mesh: Mesh, lo: float, hi: float, worst: float) -> str:
    """The canvas text that goes with the quality colour bar: scale, bound and worst."""
    holds = "within" if worst <= hi + 1e-9 else "ABOVE"
    # short lines: the canvas of a laptop screen is about 550 px wide
    return (f"colour: radius-to-edge ratio of each face's worse element\n"
            f"from {lo:.3f} (best) to {max(hi, worst):.3f}\n{bound_label(mesh)}: <= {hi:.3f}\n"
            f"worst element {worst:.3f} ({holds} the bound)")


def _bound_line(mesh: Mesh) -> str:
    """The summary's sentence on the quality bound that holds for `mesh`'s voxels."""
    subdivided = _subdivided(mesh)
    hi = _mesh_bound(mesh)[1]
    if _method(mesh) != "template":
        return (f"no quality bound is proven for the {_method(mesh)} method "
                f"(shaded: the template mesher's, {hi:.3f})")
    if len(set(mesh.spacing)) <= 1:
        return f"IMESH bound (square/cubic voxels): ratio <= {hi:.3f}"
    if subdivided:
        cells = " x ".join(str(f) for f in mesh.recipe.lattice.factors)
        return (f"IMESH bound for {_aspect(mesh.spacing)} voxels cut into {cells} cells: "
                f"ratio <= {hi:.3f}")
    cubic = bound_range(mesh.ndim)[1]
    return (f"IMESH bound for {_aspect(mesh.spacing)} voxels: ratio <= {hi:.3f} (the "
            f"cubic {cubic:.3f} does not hold: the spacing stretches every element)")
