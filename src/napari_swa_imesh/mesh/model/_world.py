"""Where a mesh lies: from an image's index-to-world affine to the mesh's placement.

Convention (NIfTI, nibabel's ``img.affine``): the affine maps voxel indices in the array's
axis order to world coordinates x, y(, z); voxel centres lie at integer indices, so voxel
``n`` spans ``n - 0.5 .. n + 0.5``. The mesher puts pixel corner ``c`` (0 .. shape) at
``p = c * s``. With ``s`` the affine's voxel sizes (the norms of its columns) that corner's
world position is::

    A @ (p / s - 0.5) + t  =  (A diag(1/s)) @ p + (t - A @ 0.5)

so a mesh keeps its points in the image frame (``[0, shape * s]``: what the checks, facet
groups, quality and simulation use) and carries ``world = [[A diag(1/s), t - A @ 0.5],
[0, 1]]`` (``Mesh.world``), which the writers apply. Without shear ``A diag(1/s)`` is a
rotation or a reflection, so lengths, angles and the quality metrics are the same in the
file as in the mesh.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["world_from_affine", "voxel_sizes", "SHEAR_TOLERANCE"]

#: Largest |cos| between two unit columns of an affine still taken as perpendicular:
#: NIfTI stores its matrices in float32 (relative error ~1e-7).
SHEAR_TOLERANCE = 1e-5


def _linear_part(affine, ndim: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(ndim, ndim) linear part and (ndim,) translation of `affine`, checked."""
    arr = np.asarray(affine)
    n = ndim + 1
    if arr.dtype.kind not in "biuf" or arr.ndim != 2 or arr.shape[0] != arr.shape[1] or \
            arr.shape[0] not in (n, 4) or arr.shape[0] < n:
        shapes = " or ".join(dict.fromkeys([f"({n}, {n})", "(4, 4)"]))
        raise ValueError(f"{name} must be a {shapes} matrix of numbers for a {ndim}-D "
                         f"image; got {arr.dtype} of shape {arr.shape}.")
    arr = arr.astype(np.float64)
    m = arr.shape[0] - 1
    last = np.eye(m + 1)[m]
    if not np.isfinite(arr).all() or not np.allclose(arr[m], last):
        raise ValueError(f"{name} must be finite with last row {last.tolist()}; got "
                         f"{arr.tolist()}.")
    linear, shift = arr[:ndim, :ndim], arr[:ndim, m]
    if m > ndim:
        # a 2-D image in a 3-D world: its plane must be a plane of constant z
        tilt = np.abs(arr[ndim:m, :ndim]).max()
        if tilt > SHEAR_TOLERANCE * np.abs(linear).max():
            raise ValueError(f"{name} tilts the {ndim}-D image out of the world's x-y plane "
                             f"(z changes along its axes: {arr[ndim:m, :ndim].tolist()}); a "
                             f"{ndim}-D mesh cannot lie there. Mesh it as a 3-D image of one "
                             "slice (labels[..., None]), or in index space (without the "
                             "affine; --index-space on the command line).")
    sv = np.linalg.svd(linear, compute_uv=False)
    if not sv[-1] > 1e-12 * sv[0]:
        raise ValueError(f"{name} is singular (its voxel axes {linear.T.tolist()} span less "
                         f"than {ndim}-D), so it places no voxel anywhere; fix the file's "
                         "qform/sform, or mesh in index space (without the affine; "
                         "--index-space on the command line).")
    return linear, shift


def voxel_sizes(affine, ndim: int | None = None) -> tuple[float, ...]:
    """Size of a voxel along each array axis: the norms of the affine's columns.

    Parameters
    ----------
    affine : (d+1, d+1) or (4, 4) array_like
        Index-to-world affine (e.g. nibabel's ``img.affine``).
    ndim : int, optional
        Dimension of the image (default: the affine's).

    Returns
    -------
    tuple of float
        One value per array axis.

    Examples
    --------
    >>> voxel_sizes([[0, -2, 0, 5], [3, 0, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]])
    (3.0, 2.0, 1.0)
    """
    nd = np.asarray(affine).shape[0] - 1 if ndim is None else int(ndim)
    linear, _ = _linear_part(affine, nd, "affine")
    return tuple(float(v) for v in np.linalg.norm(linear, axis=0))


def world_from_affine(affine, ndim: int, *, name: str = "affine"
                      ) -> tuple[tuple[float, ...], np.ndarray]:
    """Spacing to mesh with and the ``Mesh.world`` matrix that places the mesh.

    Parameters
    ----------
    affine : (d+1, d+1) or (4, 4) array_like
        Index-to-world affine of the label image, voxel centres at integer indices
        (NIfTI; nibabel's ``img.affine``). A (4, 4) affine of a 2-D image must keep the
        image in a plane of constant z (which the 2-D mesh then drops).
    ndim : int
        Dimension of the label image (2 or 3).
    name : str
        What to call the affine in messages.

    Returns
    -------
    spacing : tuple of float
        The voxel sizes (:func:`voxel_sizes`): mesh with these.
    world : (d+1, d+1) ndarray of float64
        Maps the mesh's points (corner index times `spacing`) to world x, y(, z).

    Raises
    ------
    ValueError
        For a matrix of the wrong shape, non-finite values, a singular linear part, or a
        2-D image tilted out of the world's x-y plane.

    Warns
    -----
    UserWarning
        When the affine shears (voxel axes not perpendicular): the mesh is still placed
        exactly, but its elements are sheared like the voxels, so their quality in the
        file is worse than the quality the mesh records (that of the unsheared grid).

    Examples
    --------
    A 2-D image of 2 x 3 voxels, the x axis flipped, voxel 0 centred at (10, 0):

    >>> spacing, world = world_from_affine([[-2, 0, 10], [0, 3, 0], [0, 0, 1]], 2)
    >>> spacing
    (2.0, 3.0)
    >>> (world @ [0, 0, 1]).tolist()     # corner 0: half a voxel before voxel 0's centre
    [11.0, -1.5, 1.0]
    """
    linear, shift = _linear_part(affine, ndim, name)
    sizes = np.linalg.norm(linear, axis=0)
    unit = linear / sizes                                    # (d, d) unit voxel axes
    cosines = np.abs(unit.T @ unit - np.eye(ndim)).max()
    if cosines > SHEAR_TOLERANCE:
        angle = float(np.degrees(np.arccos(min(cosines, 1.0))))
        warnings.warn(f"{name} shears the voxels (two voxel axes {angle:.3g} degrees apart, "
                      "not 90): the mesh is placed exactly, but its elements are sheared "
                      "like the voxels, so their quality in the file is worse than the "
                      "quality reported (that of the unsheared voxel grid).", stacklevel=2)
    world = np.eye(ndim + 1)
    world[:ndim, :ndim] = unit
    world[:ndim, ndim] = shift - linear.sum(axis=1) / 2
    return tuple(float(s) for s in sizes), world


def image_placement(path, ndim: int) -> tuple[tuple[float, ...], np.ndarray] | None:
    """Spacing and ``Mesh.world`` that place the mesh of a label image file in its world.

    Parameters
    ----------
    path : str or Path
        The label image file; only a NIfTI file (``.nii``, ``.nii.gz``) has a placement,
        read from its header's affine.
    ndim : int
        Dimension of the label image (2 or 3).

    Returns
    -------
    (spacing, world) or None
        As :func:`world_from_affine` for a NIfTI file; None for other formats (the
        image's own frame) and for an image that is not 2-D or 3-D (the label checks
        refuse it with their own sentence).

    Raises
    ------
    ValueError
        As :func:`world_from_affine`, naming the file's affine.
    """
    from pathlib import Path

    from ...io import is_nifti, read_affine

    if not is_nifti(path) or ndim not in (2, 3):
        return None
    return world_from_affine(read_affine(path), ndim,
                             name=f"the affine of {Path(path).name}")
