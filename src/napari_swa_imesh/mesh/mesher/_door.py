"""The door of the mesher: its arguments checked once, in one wording.

:func:`~._imesh.plan_mesh` (and through it :func:`~._imesh.mesh_labels`) calls these, and
so does adaptive refinement when it meshes the labels of a mesh again; then the workers
trust what they get.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from ..._validation import as_labels, normalize_spacing
from ..checks._checks import count_excluded
from ..model._types import Mesh
from ._coarsen import check_coarsen
from ._lattice import Lattice, choose_lattice

__all__ = ["METHODS", "resolution_arguments", "check_periodic", "check_max_size",
           "record_coarsening", "warn_lost_materials"]

METHODS = ("template", "delaunay")


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


def record_coarsening(mesh: Mesh, report: dict) -> None:
    """Say on `mesh` that its labels were coarsened first (``recipe.coarsen``, the volume
    changes in ``info["coarsen"]``) and warn about materials the coarsening removed."""
    mesh.info["coarsen"] = report
    if mesh.recipe is None:
        raise ValueError("record_coarsening takes a mesh made by the mesher (with a recipe).")
    mesh.recipe = dataclasses.replace(mesh.recipe, coarsen=int(report["level"]))
    # warnings.warn <- here <- MeshPlan.steps <- run <- mesh_labels <- the caller
    warn_lost_materials(report, mesh.material_names, stacklevel=6)


def warn_lost_materials(report: dict, names: dict | None = None, *,
                        stacklevel: int = 3) -> None:
    """Warn (naming them) about materials the coarsening removed entirely."""
    if report.get("lost"):
        lost = ", ".join(f"{m}" + (f" ({names[m]})" if names and m in names else "")
                         for m in report["lost"])
        warnings.warn(f"coarsening by 2^{report['level']} voxels removed material(s) {lost} "
                      "entirely: they are thinner than a block. Use a smaller --coarsen to "
                      "keep them.", UserWarning, stacklevel=stacklevel)


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
