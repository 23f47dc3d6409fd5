"""Reading images and writing label images, keeping voxel spacing.

Supported: ``.tif/.tiff`` (tifffile; ImageJ spacing and resolution tags), ``.png``,
``.jpg/.jpeg`` (imageio), ``.npy`` (no pickles), ``.nii/.nii.gz`` (nibabel; spacing from
the header zooms). Arrays keep the order in which the file stores them; spacing is given
per array axis in that same order.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from ._cli_util import check_writable
from ._validation import normalize_spacing

__all__ = ["read_image", "write_labels", "image_suffix", "IMAGE_SUFFIXES"]

IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".jpg", ".jpeg", ".npy", ".nii", ".nii.gz")


def image_suffix(path) -> str:
    """Lower-case suffix of `path`, treating ``.nii.gz`` as one suffix."""
    name = Path(path).name.lower()
    if name.endswith(".nii.gz"):
        return ".nii.gz"
    return Path(name).suffix


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
        One value per axis of `image`; 1.0 where the file says nothing.

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, unknown suffix, or a file the reader cannot parse.
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
    except Exception as exc:  # a corrupt file surfaces as many reader-specific errors
        raise ValueError(f"cannot read {p} as a {suffix} image: {exc}") from exc
    if gray and image.ndim == 3 and image.shape[-1] in (3, 4):
        from skimage.color import rgb2gray, rgba2rgb

        rgb = rgba2rgb(image) if image.shape[-1] == 4 else image
        image = rgb2gray(rgb)
    spacing = normalize_spacing(spacing, image.ndim) if spacing and len(spacing) in (1, image.ndim) \
        else normalize_spacing(None, image.ndim)
    return image, spacing


def _read_by_suffix(p: Path, suffix: str):
    if suffix in (".tif", ".tiff"):
        return _read_tiff(p)
    if suffix in (".png", ".jpg", ".jpeg"):
        import imageio.v3 as iio

        return np.asarray(iio.imread(p)), None
    if suffix == ".npy":
        return np.load(p, allow_pickle=False), None
    import nibabel as nib

    img = nib.load(str(p))
    image = np.asarray(img.dataobj)
    return image, tuple(float(z) for z in img.header.get_zooms()[: image.ndim])


def _read_tiff(p: Path):
    import tifffile

    with tifffile.TiffFile(p) as tif:
        image = tif.asarray()
        spacing = [1.0] * image.ndim
        page = tif.pages[0]
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
        except Exception:  # spacing is best effort; the pixels are what matters
            spacing = [1.0] * image.ndim
    return image, tuple(spacing)


def write_labels(path, labels: np.ndarray, *, spacing=None, force: bool = False) -> Path:
    """Write a label image in the format its suffix names, without clobbering files.

    Parameters
    ----------
    path : str or Path
        ``.npy``, ``.tif/.tiff``, ``.nii/.nii.gz`` or ``.png`` (2-D, labels < 65536).
    labels : ndarray of int
        Label image.
    spacing : sequence of float, optional
        Voxel spacing to record (TIFF resolution / ImageJ spacing, NIfTI zooms).
    force : bool
        Replace an existing file. Without it an existing file is an error.

    Returns
    -------
    Path
        The written file. It is written to a temporary name first and moved into place,
        so a failed write never leaves a half file where the user's was.
    """
    p = check_writable(path, force=force)
    labels = np.asarray(labels)
    suffix = image_suffix(p)
    sp = normalize_spacing(spacing, labels.ndim)
    if labels.size and labels.min() >= 0 and labels.max() < 256:
        data = labels.astype(np.uint8)
    elif labels.size and labels.min() >= 0 and labels.max() < 65536:
        data = labels.astype(np.uint16)
    else:
        data = labels.astype(np.int32)
    if suffix not in (".npy", ".tif", ".tiff", ".nii", ".nii.gz", ".png"):
        raise ValueError(
            f"cannot write labels as {suffix!r}; use .npy, .tif, .nii.gz or .png."
        )
    if suffix == ".png" and (labels.ndim != 2 or data.dtype == np.int32):
        raise ValueError(
            f"PNG holds 2-D labels below 65536; got shape {labels.shape}. Use .tif or .nii.gz."
        )
    fd, tmp = tempfile.mkstemp(prefix=".swa-imesh-", suffix=suffix, dir=p.parent or ".")
    os.close(fd)
    try:
        if suffix == ".npy":
            with open(tmp, "wb") as fh:
                np.save(fh, data)
        elif suffix in (".tif", ".tiff"):
            import tifffile

            meta = {"spacing": sp[-3]} if data.ndim == 3 else {}
            tifffile.imwrite(
                tmp, data, imagej=data.ndim in (2, 3) and data.dtype != np.int32,
                resolution=(1.0 / sp[-1], 1.0 / sp[-2]), metadata=meta or None,
            )
        elif suffix in (".nii", ".nii.gz"):
            import nibabel as nib

            affine = np.diag(list(sp[:3]) + [1.0] * (4 - min(3, data.ndim)))[:4, :4]
            img = nib.Nifti1Image(data, affine)
            img.header.set_zooms(sp)
            nib.save(img, tmp)
        else:
            import imageio.v3 as iio

            iio.imwrite(tmp, data, extension=".png")
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return p
