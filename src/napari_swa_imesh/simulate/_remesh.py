"""A mesh for a k_eff run that asks for another resolution or the periodic protocol.

Interface refinement and periodic faces are properties of the mesh, made by
:func:`~napari_swa_imesh.mesh.mesh_labels`; a mesh made without them cannot be given them
afterwards. A tool that holds a mesh (the napari Simulate tab holds the Mesh tab's) and is
asked for refine level K or the periodic protocol therefore meshes the label image again,
with everything else the mesh was made with (method, excluded materials, spacing, anisotropy
subdivision, size cap, names, world placement), and checks that the labels given are the
image the mesh came from: same shape, and every material the same volume.
"""

from __future__ import annotations

import numpy as np

from ..mesh import Mesh, mesh_labels, signed_volumes

__all__ = ["mesh_refine", "needs_remesh", "remesh"]


def mesh_refine(mesh: Mesh) -> int:
    """The interface refinement level `mesh` was made with (0 when it does not say)."""
    return 0 if mesh.recipe is None else mesh.recipe.refine


def needs_remesh(mesh: Mesh, *, refine: int, periodic: bool) -> bool:
    """Whether a run with `refine` and (for the periodic protocol) periodic faces needs a
    new mesh: the level differs from the mesh's, or periodic faces are wanted and the mesh
    was not made with them (a periodic mesh serves the mixed protocol as well)."""
    made_periodic = mesh.recipe is not None and mesh.recipe.periodic
    return mesh_refine(mesh) != int(refine) or (bool(periodic) and not made_periodic)


def _material_volumes(mesh: Mesh) -> dict[int, float]:
    materials, inverse = np.unique(mesh.material, return_inverse=True)
    volumes = np.bincount(inverse, weights=signed_volumes(mesh.points, mesh.cells),
                          minlength=materials.size)
    return dict(zip(materials.tolist(), volumes.tolist()))


def remesh(mesh: Mesh, labels, *, refine: int, periodic: bool) -> Mesh:
    """Mesh `labels` again as `mesh` was made, with refine level `refine` and periodic faces.

    Parameters
    ----------
    mesh : Mesh
        Made by :func:`~napari_swa_imesh.mesh.mesh_labels` (its ``recipe`` says how;
        without one, the defaults: the template method, nothing excluded).
    labels : (M, N[, P]) array_like of int
        The label image `mesh` was made from.
    refine : int
        Interface refinement level, 0 .. 4.
    periodic : bool
        Give opposite faces matching facets (for the periodic protocol).

    Returns
    -------
    Mesh
        With `mesh`'s method, excluded materials, spacing, subdivision, size cap, names and
        world placement.

    Raises
    ------
    ValueError
        Labels of another shape, or whose materials' volumes differ from the mesh's (not
        the image the mesh was made from); a coarsened mesh, or one that does not record
        its image (mesh the labels with the refine level wanted instead).

    Examples
    --------
    >>> labels = np.ones((4, 4), dtype=np.uint8); labels[1:3, 1:3] = 2
    >>> coarse = mesh_labels(labels)
    >>> fine = remesh(coarse, labels, refine=1, periodic=False)
    >>> mesh_refine(fine), fine.n_cells > coarse.n_cells
    (1, True)
    """
    labels = np.asarray(labels)
    recipe = mesh.recipe
    if not mesh.records_box:
        raise ValueError("this mesh does not record the label image it was made from (a "
                         "mesh read from a file?); mesh the labels with the refine level "
                         "and periodic faces wanted instead.")
    if recipe is not None and recipe.coarsen:
        raise ValueError("this mesh was coarsened, so its labels cannot be meshed again "
                         "the same way here; mesh them with the refine level wanted "
                         "instead.")
    if tuple(labels.shape) != tuple(mesh.shape):
        raise ValueError(f"the labels are {labels.shape} but the mesh was made from "
                         f"{tuple(mesh.shape)} labels; give the label image of this mesh.")
    subdivided = recipe is not None and recipe.subdivided
    lattice = None if recipe is None else recipe.lattice   # set whenever subdivided
    new = mesh_labels(labels, method="template" if recipe is None else recipe.method,
                      exclude=() if recipe is None else recipe.exclude,
                      spacing=mesh.spacing or None,
                      material_names=dict(mesh.material_names), refine=refine,
                      max_size=None if recipe is None else recipe.max_size,
                      subdivide=subdivided,
                      max_aspect=lattice.max_aspect if subdivided and lattice is not None else None,
                      periodic=periodic)
    old_volumes, new_volumes = _material_volumes(mesh), _material_volumes(new)
    same = old_volumes.keys() == new_volumes.keys() and all(
        np.isclose(new_volumes[m], v, rtol=1e-9, atol=0) for m, v in old_volumes.items())
    if not same:
        raise ValueError("these labels give other material volumes than the mesh: they are "
                         "not the image the mesh was made from; give that label image.")
    new.world = mesh.world          # already checked when `mesh` was made
    return new
