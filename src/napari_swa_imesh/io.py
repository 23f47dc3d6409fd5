"""Reading images and writing label images, keeping voxel spacing.

Supported: ``.tif/.tiff`` (tifffile; ImageJ spacing and resolution tags), ``.png``,
``.jpg/.jpeg`` (imageio), ``.npy`` (no pickles), ``.nii/.nii.gz`` (nibabel; spacing from
the affine the standard chooses, see :func:`read_affine`). Arrays keep the order in which
the file stores them; spacing is given per array axis in that same order. A NIfTI file
also places its voxels in a world frame (:func:`read_affine`: nibabel's ``img.affine``,
voxel centres at integer indices); the other formats place voxel corner 0 at the origin,
axes scaled by the spacing. The atomic writer every output goes through
(:func:`check_writable`, :func:`atomic_write`) lives in ``_atomic`` and is re-exported here.
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

import numpy as np

from ._atomic import atomic_write, check_writable, is_store
from ._headers import Refused, check_affine, complete_frame, load_nifti, load_npy, nifti_placement
from ._validation import label_dtype, normalize_spacing

__all__ = ["read_image", "read_affine", "is_nifti", "grid_affine", "write_labels",
           "write_labels_to", "label_array", "check_label_format", "image_suffix",
           "IMAGE_SUFFIXES", "LABEL_SUFFIXES", "check_writable", "atomic_write", "is_store",
           "check_figure_path", "write_figure", "load_npy"]

LABEL_SUFFIXES = (".npy", ".tif", ".tiff", ".nii", ".nii.gz", ".png")

IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".jpg", ".jpeg", ".npy", ".nii", ".nii.gz")


def image_suffix(path) -> str:
    """Lower-case suffix of `path`, treating ``.nii.gz`` as one suffix."""
    name = Path(path).name.lower()
    if name.endswith(".nii.gz"):
        return ".nii.gz"
    return Path(name).suffix


def is_nifti(path) -> bool:
    """Whether `path` names a NIfTI file (``.nii`` or ``.nii.gz``)."""
    return image_suffix(path) in (".nii", ".nii.gz")


def read_affine(path) -> np.ndarray | None:
    """The index-to-world affine of a NIfTI file (header only), or None for other formats.

    Parameters
    ----------
    path : str or Path
        Any file :func:`read_image` reads.

    Returns
    -------
    (4, 4) ndarray of float64 or None
        nibabel's ``img.affine`` (the sform when ``sform_code > 0``, else the qform when
        ``qform_code > 0``, else the zooms): maps voxel indices, in the array order
        :func:`read_image` gives, to world x, y, z, with voxel centres at integer indices.
        None for TIFF, PNG, JPEG and ``.npy``, whose voxel corner 0 lies at the origin.
        :func:`read_image` gives the norms of its spatial columns as the spacing.

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, a NIfTI header nibabel cannot parse, or one whose chosen placement
        gives no voxel size: a NaN, infinite or singular sform or qform, or a zero,
        negative or NaN ``pixdim`` where the qform or the zooms are used (nibabel would
        read such a size as 1).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "l.nii.gz"
    >>> _ = write_labels(path, np.ones((2, 3, 4), np.uint8), spacing=(2, 1, 1))
    >>> np.diag(read_affine(path)).tolist()
    [2.0, 1.0, 1.0, 1.0]
    """
    p = Path(path)
    if not is_nifti(p):
        return None
    if not p.is_file():
        raise FileNotFoundError(f"no image file at {p}; check the path.")
    return nifti_placement(p, load_nifti(p))[0]


def grid_affine(affine, step: int, ndim: int) -> np.ndarray:
    """Index-to-world affine of a grid of `step`-voxel blocks (tiles) of an image.

    Block t covers voxels ``t*step .. t*step + step - 1`` along each of the first `ndim`
    axes, so its centre is voxel ``t*step + (step - 1) / 2``.

    Examples
    --------
    >>> grid_affine(np.diag([2.0, 1.0, 1.0, 1.0]), 4, 2)[:2].tolist()
    [[8.0, 0.0, 0.0, 3.0], [0.0, 4.0, 0.0, 1.5]]
    """
    block = np.eye(len(affine))
    for axis in range(ndim):
        block[axis, axis], block[axis, -1] = step, (step - 1) / 2
    return np.asarray(affine, dtype=np.float64) @ block


def read_image(path, *, gray: bool = False) -> tuple[np.ndarray, tuple[float, ...]]:
    """Read an image file and its voxel spacing.

    Parameters
    ----------
    path : str or Path
        A ``.tif/.tiff``, ``.png``, ``.jpg``, ``.npy`` or ``.nii/.nii.gz`` file.
    gray : bool
        Convert an RGB(A) picture to grey (luminance) instead of returning 3-4 channels.

    Returns
    -------
    image : ndarray
        As stored (dtype kept).
    spacing : tuple of float
        One value per axis of `image`; 1.0 where the file says nothing. NIfTI: the voxel
        sizes of :func:`read_affine` (the norms of its columns), checked before the pixels
        are read.

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, unknown suffix, a file the reader cannot parse (a ``.npy`` that is
        not one, or holds Python objects), or a NIfTI header that places no voxel
        (:func:`read_affine`).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no image file at {p}; check the path.")
    suffix = image_suffix(p)
    if suffix not in IMAGE_SUFFIXES:
        raise ValueError(
            f"cannot read {p.name}: unknown suffix {suffix!r}; use one of "
            f"{', '.join(IMAGE_SUFFIXES)}."
        )
    try:
        image, spacing = _read_by_suffix(p, suffix)
    except Refused:
        raise
    except Exception as exc:  # a corrupt file surfaces as many reader-specific errors
        raise ValueError(f"cannot read {p} as a {suffix} image: {exc}") from exc
    if gray and image.ndim == 3 and image.shape[-1] in (3, 4):
        from skimage.color import rgb2gray, rgba2rgb

        rgb = rgba2rgb(image) if image.shape[-1] == 4 else image
        image = rgb2gray(rgb)
    try:
        spacing = normalize_spacing(spacing if spacing and len(spacing) in (1, image.ndim)
                                    else None, image.ndim)
    except ValueError as exc:     # a zero ImageJ spacing, a size beyond SPACING_RANGE...
        raise ValueError(f"the voxel spacing stored in {p.name} is unusable: {exc}") from None
    return image, spacing


def _read_by_suffix(p: Path, suffix: str):
    if suffix in (".tif", ".tiff"):
        return _read_tiff(p)
    if suffix in (".png", ".jpg", ".jpeg"):
        import imageio.v3 as iio

        return np.asarray(iio.imread(p)), None
    if suffix == ".npy":
        return load_npy(p), None
    img = load_nifti(p)
    _, spatial = nifti_placement(p, img)   # refused before the pixels are read
    image = np.asarray(img.dataobj)
    # axes past the third (time, channels) have no place in the affine: their pixdim, 1
    # where it is no size (every command refuses 4-D images anyway)
    extra = [float(z) if np.isfinite(z) and z > 0 else 1.0
             for z in img.header.get_zooms()[len(spatial):image.ndim]]
    return image, spatial + tuple(extra)


def _read_tiff(p: Path):
    import tifffile

    with tifffile.TiffFile(p) as tif:
        image = tif.asarray()
        spacing = [1.0] * image.ndim
        page = cast("tifffile.TiffPage", tif.pages[0])   # the first is a page, not a frame
        try:
            xres = page.tags.get("XResolution")
            yres = page.tags.get("YResolution")
            if xres is not None and yres is not None and image.ndim >= 2:
                xn, xd = xres.value
                yn, yd = yres.value
                if xn and yn:
                    spacing[-1] = xd / xn
                    spacing[-2] = yd / yn
            ij = tif.imagej_metadata or {}
            if "spacing" in ij and image.ndim >= 3:
                spacing[-3] = float(ij["spacing"])
            shaped = (tif.shaped_metadata or ({},))[0] or {}
            if len(shaped.get("spacing_per_axis", ())) == image.ndim:
                spacing = [float(v) for v in shaped["spacing_per_axis"]]
        except Exception:  # spacing is best effort; the pixels are what matters
            spacing = [1.0] * image.ndim
    return image, tuple(spacing)


def label_array(labels, *, name: str = "labels") -> np.ndarray:
    """`labels` in the smallest integer dtype that holds every value exactly.

    Unsigned (uint8 .. uint64) when no value is negative, else signed (int8 .. int64):
    the file/display side of the one label-dtype policy (``label_dtype(labels,
    smallest=True)`` in ``_validation``).
    Boolean and whole-number float arrays are accepted; anything that would change a
    value (fractions, NaN, values beyond 64 bits) is refused.

    Parameters
    ----------
    labels : array_like of int, bool or whole-valued float
        The label image.
    name : str
        What to call it in error messages.

    Returns
    -------
    ndarray of int or uint
        `labels` itself when already in that dtype, else a converted copy.

    Examples
    --------
    >>> label_array([0, 3, 70000]).dtype
    dtype('uint32')
    >>> int(label_array(np.array([2**40 + 3], np.int64))[0]) == 2**40 + 3
    True
    """
    arr = np.asarray(labels)
    if arr.dtype.kind == "b":
        return arr.astype(np.uint8)
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or not np.array_equal(arr, np.round(arr)):
            raise ValueError(f"{name} hold non-integer values (dtype {arr.dtype}); a label "
                             "image holds whole numbers. Round or segment it first.")
        lo, hi = (float(arr.min()), float(arr.max())) if arr.size else (0.0, 0.0)
        if lo < -2.0 ** 63 or hi >= (2.0 ** 64 if lo >= 0 else 2.0 ** 63):
            raise ValueError(f"{name} hold values beyond 64-bit integers ({lo:g} .. {hi:g}); "
                             "relabel them first.")
        arr = arr.astype(np.uint64 if lo >= 0 else np.int64)
    elif arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be integers; got dtype {arr.dtype}.")
    if arr.size == 0:
        return arr.astype(np.uint8)
    return arr.astype(label_dtype(arr, smallest=True, name=name), copy=False)


def check_label_format(path, labels: np.ndarray) -> None:
    """Raise ValueError unless `path`'s format holds `labels` (from :func:`label_array`)
    exactly: its suffix, dimensionality and value range."""
    suffix = image_suffix(path)
    if suffix not in LABEL_SUFFIXES:
        raise ValueError(
            f"cannot write labels as {Path(path).name!r}: unknown suffix {suffix!r}; use "
            f"{', '.join(LABEL_SUFFIXES)}."
        )
    if suffix == ".png":
        if labels.ndim != 2 or labels.dtype not in (np.uint8, np.uint16):
            raise ValueError(
                f"PNG holds 2-D labels from 0 to 65535; got shape {labels.shape} with "
                f"values up to {labels.max() if labels.size else 0}. Use .tif, .nii.gz or "
                ".npy."
            )
    if suffix in (".nii", ".nii.gz") and labels.ndim > 7:
        raise ValueError(f"NIfTI holds up to 7 axes; got {labels.ndim}. Use .npy.")


def write_labels(path, labels, *, spacing=None, origin=None, affine=None,
                 force: bool = False) -> Path:
    """Write a label image in the format its suffix names; values are kept exactly.

    Parameters
    ----------
    path : str or Path
        ``.npy``, ``.tif/.tiff``, ``.nii/.nii.gz`` or ``.png`` (2-D, labels 0..65535).
    labels : ndarray of int
        Label image. Stored in the smallest integer type that holds every value
        (:func:`label_array`); a format that cannot hold them is an error, never a wrap.
    spacing : sequence of float, optional
        Size of one array element per axis, in physical units (TIFF resolution and
        ImageJ spacing, NIfTI zooms).
    origin : sequence of float, optional
        Physical position of the centre of element 0 per axis (NIfTI affine translation,
        ImageJ ``xorigin``/``yorigin``/``zorigin``); default 0.
    affine : (4, 4) array_like, optional
        NIfTI only: the index-to-world affine of `labels` (e.g. the :func:`read_affine` of
        the image they label, or its :func:`grid_affine` for tile labels), written as the
        sform and qform instead of `spacing` and `origin`; the zooms are its voxel sizes.
    force : bool
        Replace an existing file. Without it an existing file is an error.

    Returns
    -------
    Path
        The written file (written through :func:`atomic_write`).
    """
    data = label_array(labels)
    check_label_format(path, data)
    if affine is not None and not is_nifti(path):
        raise ValueError(f"an affine can only be written to NIfTI (.nii, .nii.gz), not "
                         f"{Path(path).name!r}; give spacing and origin instead.")
    if affine is not None:
        check_affine(affine, min(data.ndim, 3))
    with atomic_write([path], force=force) as (tmp,):
        write_labels_to(tmp, data, spacing=spacing, origin=origin, affine=affine)
    return Path(path)


def write_labels_to(tmp, data: np.ndarray, *, spacing=None, origin=None, affine=None
                    ) -> None:
    """Write checked labels (:func:`label_array`, :func:`check_label_format`) to `tmp`,
    a temporary path from :func:`atomic_write` with the target's name (`affine`: NIfTI
    only, see :func:`write_labels`)."""
    suffix = image_suffix(tmp)
    sp = normalize_spacing(spacing, data.ndim)
    org = (0.0,) * data.ndim if origin is None else tuple(float(v) for v in origin)
    if suffix == ".npy":
        with open(tmp, "wb") as fh:
            np.save(fh, data)
    elif suffix in (".tif", ".tiff"):
        import tifffile

        # ImageJ files drop axes of length 1 on reading; tifffile's own shaped
        # description keeps every axis (and any integer type)
        imagej = data.ndim in (2, 3) and data.dtype in (np.uint8, np.uint16) and min(
            data.shape) > 1
        meta: dict = {}
        if data.ndim == 3:
            meta["spacing"] = sp[-3]
        # ImageJ calibration: physical = (index - origin) * spacing, origin in pixels
        for key, axis in (("xorigin", -1), ("yorigin", -2), ("zorigin", -3)):
            if data.ndim >= -axis and org[axis] != 0:
                meta[key] = -org[axis] / sp[axis]
        if not imagej:
            meta.pop("zorigin", None)
            meta.update({"spacing_per_axis": list(sp), "origin": list(org)})
        tifffile.imwrite(tmp, data, imagej=imagej, resolution=(1.0 / sp[-1], 1.0 / sp[-2]),
                         metadata=meta or None)
    elif suffix in (".nii", ".nii.gz"):
        import nibabel as nib

        if affine is None:
            affine = np.eye(4)
            for axis in range(min(3, data.ndim)):
                affine[axis, axis] = sp[axis]
                affine[axis, 3] = org[axis]
        else:
            affine = complete_frame(np.asarray(affine, dtype=np.float64), data.ndim)
            sizes = np.linalg.norm(affine[:3, :3], axis=0)
            sp = tuple(float(sizes[a]) if a < 3 else sp[a] for a in range(data.ndim))
        img = nib.Nifti1Image(data, affine, dtype=data.dtype)
        img.header.set_zooms(sp)
        nib.save(img, str(tmp))
    else:
        import imageio.v3 as iio

        iio.imwrite(tmp, data, extension=".png")


def check_figure_path(path, *, force: bool = False) -> Path:
    """Check that `path` may be written and that matplotlib writes its format.

    Raises
    ------
    ValueError
        The suffix is no format matplotlib can write (the message lists them).
    """
    from matplotlib.backend_bases import FigureCanvasBase

    p = check_writable(path, force=force)
    formats = sorted(FigureCanvasBase.get_supported_filetypes())
    if p.suffix.lower().lstrip(".") not in formats:
        raise ValueError(f"cannot write a plot as {p.name!r}: the suffix must name an image "
                         f"format ({', '.join('.' + f for f in formats)}).")
    return p


def write_figure(figure, path, *, force: bool = False, dpi: int = 120) -> Path:
    """Save a matplotlib figure through :func:`atomic_write`."""
    check_figure_path(path, force=force)
    with atomic_write([path], force=force) as (tmp,):
        figure.savefig(tmp, dpi=dpi)
    return Path(path)
