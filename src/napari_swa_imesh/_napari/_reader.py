"""Readers: NIfTI and TIFF images with their voxel spacing, and meshes back as Surfaces.

TIFF (.tif, .tiff): the voxel spacing the command line reads (:func:`..io.read_image`:
ImageJ ``spacing`` and resolution tags, OME physical sizes) becomes the layer's ``scale``,
so the sample boxes, the mesh and the simulation are in the file's units, as from the
command line.

Meshes (every suffix :func:`..mesh.write_mesh` writes): the boundary and material-interface
faces as a Surface layer whose vertex values are the material (coloured with the plugin's
material colours), the real mesh (tetrahedra in 3-D) in the layer's metadata, so the
Simulate tab runs on it and napari's Save writes it again.

NIfTI (.nii, .nii.gz): every voxel where the file's affine puts it.

The layer's ``scale`` is the voxel size per array axis (what the widgets take as spacing)
and its ``affine`` the rest of the NIfTI affine (rotation, flip, origin); the NIfTI affine
itself rides in the metadata (``AFFINE_KEY``) so a mesh of the layer is written in that
world. napari world axis ``a`` is the NIfTI world axis nearest to array axis ``a``
(nibabel's ``io_orientation``): napari draws a 2-D slice only through the displayed rows of
the affine, and a layer whose affine sends a displayed array axis to the slider's world
axis (a plain axis swap) would be singular there. So a near-axial volume stays close to
diagonal in napari, and the mesh Surface, given the same affine, lies on it.

A volume opens as a Labels layer when its values are whole numbers and either its name
says so (a word such as ``seg``, ``labels``, ``mask``, ``aseg`` or ``atlas`` between
``_``, ``-`` or ``.``) or at most ``MAX_LABELS`` distinct values occur in a sample of about a
million voxels; else as an Image layer.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ._layers import AFFINE_KEY

__all__ = ["get_nifti_reader", "read_nifti", "napari_placement", "looks_like_labels",
           "LABEL_WORDS", "MAX_LABELS", "get_tiff_reader", "read_tiff", "get_mesh_reader",
           "read_mesh_layer",
           "MESH_READ_SUFFIXES"]  # noqa: F822 (defined lazily by the module __getattr__ below)


def __getattr__(name: str):
    # MESH_READ_SUFFIXES: the mesh files the reader opens, every suffix of the format
    # registry (.node/.ele as TetGen pairs); looked up there when asked, so that this
    # module, which napari imports to ask about any file, does not load the mesher
    if name == "MESH_READ_SUFFIXES":
        from ..mesh import MESH_SUFFIXES

        return tuple(MESH_SUFFIXES)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

#: Words of a file name that mark a label volume (BIDS ``dseg``, FreeSurfer ``aseg``...).
LABEL_WORDS = frozenset({"seg", "dseg", "segmentation", "label", "labels", "mask", "masks",
                         "aseg", "aparc", "parc", "parcellation", "atlas", "roi"})
#: At most this many distinct whole values in the sample make an unnamed volume labels.
MAX_LABELS = 64
_SAMPLE = 1 << 20


def get_nifti_reader(path) -> Callable | None:
    """npe2 reader command: a reader for one NIfTI file, else None."""
    if isinstance(path, (list, tuple)) or not str(path).lower().endswith((".nii", ".nii.gz")):
        return None
    return read_nifti


def napari_placement(affine, ndim: int) -> tuple[tuple[float, ...], np.ndarray]:
    """Napari ``scale`` and ``affine`` of a layer whose data have index-to-world `affine`.

    Parameters
    ----------
    affine : (4, 4) array_like
        NIfTI affine (voxel centres at integer indices, world x, y, z).
    ndim : int
        Dimension of the data (2 or 3; a 2-D image must lie in a plane of constant z).

    Returns
    -------
    scale : tuple of float
        Voxel size per array axis (the norms of the affine's columns).
    affine : (ndim+1, ndim+1) ndarray
        Maps ``scale * index`` to napari world: the NIfTI world's rotation/flip and
        origin, its axes ordered as the array axes nearest to them.

    Raises
    ------
    ValueError
        As :func:`napari_swa_imesh.mesh.world_from_affine` (singular, tilted 2-D, ...).
    """
    from nibabel.orientations import io_orientation

    from ..mesh import world_from_affine

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # shear: napari shows it as it is
        spacing, world = world_from_affine(affine, ndim)
    rotation = world[:ndim, :ndim]
    # world maps corners (index + 1/2) * spacing; napari maps voxel centres index * scale
    shift = world[:ndim, ndim] + rotation @ np.divide(spacing, 2)
    index_to_world = np.eye(ndim + 1)
    index_to_world[:ndim, :ndim], index_to_world[:ndim, ndim] = rotation * spacing, shift
    nearest = io_orientation(index_to_world)[:, 0].astype(int)   # world axis per array axis
    out = np.eye(ndim + 1)
    out[:ndim, :ndim], out[:ndim, ndim] = rotation[nearest], shift[nearest]
    return spacing, out


def looks_like_labels(data: np.ndarray, name: str) -> bool:
    """Whether a volume is a label image: whole values, and a label word in `name` or at
    most :data:`MAX_LABELS` distinct values in a sample (see the module docstring)."""
    flat = data.reshape(-1)
    sample = flat[:: max(1, flat.size // _SAMPLE)]
    if data.dtype.kind == "b":
        return True
    if data.dtype.kind == "f":
        if not (np.isfinite(sample).all() and np.array_equal(sample, np.round(sample))):
            return False
    elif data.dtype.kind not in "iu":
        return False
    if LABEL_WORDS & set(re.split(r"[^a-z0-9]+", name.lower())):
        return True
    return np.unique(sample).size <= MAX_LABELS


def read_nifti(path) -> list[tuple]:
    """Read a NIfTI file as an Image or Labels layer placed by the file's affine."""
    from ..io import label_array, read_affine, read_image

    image, zooms = read_image(path)
    affine = read_affine(path)
    name = Path(str(path)).name
    for suffix in (".gz", ".nii"):
        name = name.removesuffix(suffix)
    kwargs: dict = {"name": name, "scale": zooms, "metadata": {}}
    if image.ndim in (2, 3):
        try:
            kwargs["scale"], kwargs["affine"] = napari_placement(affine, image.ndim)
            kwargs["metadata"][AFFINE_KEY] = affine.tolist()
        except ValueError as exc:
            warnings.warn(f"{name}: {exc} Showing it with its voxel sizes only.", stacklevel=2)
    if looks_like_labels(image, name):
        return [(label_array(image, name=name), kwargs, "labels")]
    return [(image, kwargs, "image")]


def get_tiff_reader(path) -> Callable | None:
    """npe2 reader command: a reader for one TIFF file, else None."""
    if isinstance(path, (list, tuple)) or not str(path).lower().endswith((".tif", ".tiff")):
        return None
    return read_tiff


def read_tiff(path) -> list[tuple]:
    """Read a TIFF as an Image or Labels layer whose ``scale`` is the file's voxel spacing."""
    from ..io import label_array, read_image

    image, spacing = read_image(path)
    name = Path(str(path)).stem
    rgb = image.ndim == 3 and image.shape[-1] in (3, 4) and image.dtype == np.uint8
    scale = tuple(float(v) for v in spacing)[: image.ndim - 1 if rgb else image.ndim]
    kwargs: dict = {"name": name, "scale": scale}
    if rgb:
        return [(image, {**kwargs, "rgb": True}, "image")]
    if looks_like_labels(image, name):
        return [(label_array(image, name=name), kwargs, "labels")]
    return [(image, kwargs, "image")]


def get_mesh_reader(path) -> Callable | None:
    """npe2 reader command: a reader for one mesh file, else None."""
    if isinstance(path, (list, tuple)):
        return None
    from ..mesh import MESH_SUFFIXES

    if not str(path).lower().endswith(tuple(MESH_SUFFIXES)):
        return None
    return read_mesh_layer


def read_mesh_layer(path) -> list[tuple]:
    """Read a mesh file as a Surface layer coloured by material.

    The Surface holds the faces :func:`..mesh.mesh_surface` draws (the boundary and every
    material interface of a tetrahedral mesh; every triangle of a 2-D one), its vertex
    values are the material of the face's element, and its metadata the mesh itself
    (:data:`._layers.MESH_KEY`), with the element quality when the file has none.
    """
    from napari.utils.colormaps.standardize_color import transform_color

    from ..mesh import mesh_surface, radius_edge_ratio, read_mesh
    from ._layers import MESH_KEY, default_color
    from ._mesh_widget import SURFACE_VALUES_KEY

    mesh = read_mesh(path)
    if "quality" not in mesh.cell_data:
        mesh.cell_data["quality"] = radius_edge_ratio(mesh.points, mesh.cells)
    surface = mesh_surface(mesh)
    material = surface["material"]
    materials = np.unique(mesh.material)
    table = np.stack([transform_color(default_color(m))[0] for m in materials])
    colors = table[np.searchsorted(materials, material)] if len(material) else None
    metadata = {MESH_KEY: mesh, SURFACE_VALUES_KEY: {"quality": surface["quality"],
                                                     "material": material},
                "material_names": dict(mesh.material_names)}
    kwargs = {"name": Path(str(path)).name, "metadata": metadata, "vertex_colors": colors,
              "shading": "flat" if mesh.ndim == 3 else "none"}
    data = (surface["vertices"], surface["triangles"], material.astype(np.float64))
    return [(data, kwargs, "surface")]
