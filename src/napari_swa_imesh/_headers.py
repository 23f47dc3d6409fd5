"""What image files say about themselves, checked before their pixels are read.

NIfTI: which transform places the voxels (the sform, the qform or ``pixdim``, as the
standard chooses them from the header as stored) and whether it places them at all.
``.npy``: whether the file is one, and whether it holds numbers. Every reader of the
package (:func:`~napari_swa_imesh.io.read_image`, :func:`~napari_swa_imesh.io.read_affine`,
the lazy readers of :mod:`~napari_swa_imesh._zarr_io`) goes through here, so every command
refuses the same files with the same sentence. Writing: the affine a NIfTI header can
hold (:func:`check_affine`, :func:`complete_frame`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np

__all__ = ["Refused", "load_nifti", "nifti_placement", "check_affine", "complete_frame",
           "load_npy", "spans", "SPAN_TOLERANCE"]


class Refused(ValueError):
    """A refusal that already says what is wrong with the file and what to do: passed on
    as it is, not wrapped in "cannot read ..." as a reader's own error is."""


def load_nifti(p: Path):
    """``nibabel.load`` (header and a lazy data proxy), its log lines kept off stderr.

    nibabel "fixes" some header fields on loading (a zero voxel size becomes 1) and logs
    it; :func:`nifti_placement` reads the header as stored and refuses instead.
    """
    import nibabel as nib
    from nibabel.imageglobals import logger

    # disabled, not stripped of handlers: a logger without any falls back to stderr
    disabled, logger.disabled = logger.disabled, True
    try:
        return nib.load(str(p))
    except Exception as exc:  # a corrupt header surfaces as many nibabel errors
        raise Refused(f"cannot read the header of {p} as NIfTI: {exc}") from exc
    finally:
        logger.disabled = disabled


def nifti_placement(p: Path, img) -> tuple[np.ndarray, tuple[float, ...]]:
    """(affine, voxel sizes of the spatial axes) of a loaded NIfTI image, per the standard.

    The header as stored (not as nibabel fixes it) chooses the transform: the sform when
    ``sform_code > 0``, else the qform when ``qform_code > 0``, else the voxel sizes
    (``pixdim``) alone. The chosen one must place every voxel: finite, its voxel axes
    spanning the image's spatial dimensions, and for the qform and the voxel sizes a
    positive ``pixdim`` per spatial axis. An unusable sform is refused, not replaced by the
    qform: ``sform_code > 0`` says the sform is the placement, and the qform may name
    another frame (the scanner's rather than a template's). The voxel sizes returned are
    the norms of the affine's spatial columns, so a mesh and a simulation use the spacing
    the affine gives, to float32 rounding of the header.
    """
    from nibabel.openers import ImageOpener

    ndim = min(len(img.shape), 3)
    name = p.name
    try:
        with ImageOpener(str(p)) as fh:
            hdr = type(img.header).from_fileobj(fh, check=False)
        sform = int(hdr["sform_code"]) > 0
        qform = not sform and int(hdr["qform_code"]) > 0
        if not sform:
            zooms = np.asarray(hdr["pixdim"][1:1 + ndim], dtype=np.float64)
            if not (np.isfinite(zooms).all() and (zooms > 0).all()):
                shown = ", ".join(f"{z:g}" for z in zooms)
                raise Refused(
                    f"the header of {name} gives voxel size(s) {shown} (pixdim), and a voxel "
                    "size must be positive and finite; fix pixdim in the header (or store "
                    "an sform with sform_code > 0) with the tool that wrote it.")
            if qform:
                hdr["pixdim"][0] = -1.0 if hdr["pixdim"][0] < 0 else 1.0  # qfac 0 means 1
        affine = np.asarray(hdr.get_best_affine(), dtype=np.float64)
    except Refused:
        raise
    except Exception as exc:  # a corrupt header surfaces as many nibabel errors
        raise Refused(f"cannot read the header of {p} as NIfTI: {exc}") from exc
    what = "sform" if sform else "qform" if qform else "pixdim affine"
    used = affine[:3, list(range(ndim)) + [3]]
    columns = affine[:3, :ndim]
    finite = bool(np.isfinite(used).all())
    if not (finite and spans(columns)):
        fault = "is not finite (NaN or infinite)" if not finite else (
            f"is singular (its voxel axes span less than {ndim}-D)")
        fix = ("fix the sform in the header, or set sform_code to 0 if the qform is right"
               if sform else "fix the qform in the header")
        raise Refused(f"the {what} of {name} {fault}, so it gives no voxel size or "
                      f"position; {fix} (e.g. with nibabel or the tool that wrote it).")
    return affine, tuple(float(v) for v in np.linalg.norm(columns, axis=0))


#: Smallest singular value of an affine's unit voxel axes that still spans their space:
#: NIfTI stores float32 (relative error ~6e-8), so parallel axes come back about 1e-7
#: apart, and no scanner's axes are within 1e-5 rad of each other.
SPAN_TOLERANCE = 1e-5


def spans(columns: np.ndarray) -> bool:
    """Whether the (3, k) voxel axes `columns` span k dimensions, up to float32 storage
    (the angle between them, not their lengths: voxels may be of any aspect)."""
    norms = np.linalg.norm(columns, axis=0)
    if not (norms > 0).all():
        return False
    return bool(np.linalg.svd(columns / norms, compute_uv=False)[-1] > SPAN_TOLERANCE)


def check_affine(affine, ndim: int) -> None:
    """Refuse an affine NIfTI cannot store or read back as a placement (nibabel raises
    HeaderDataError when it writes a singular one as the qform)."""
    a = np.asarray(affine, dtype=np.float64)
    if not (a.shape == (4, 4) and np.isfinite(a).all() and spans(a[:3, :ndim])):
        raise ValueError(f"the affine to write must be a finite (4, 4) matrix whose voxel axes "
                         f"span {ndim}-D; got {a.tolist()}. Give the affine of the image the "
                         "labels belong to (read_affine).")


def complete_frame(affine: np.ndarray, ndim: int) -> np.ndarray:
    """`affine` with unit columns orthogonal to the image's axes where a 1-D or 2-D
    image's affine has none (a zero z column): NIfTI stores a 3-D frame and nibabel
    cannot write a singular one; the axes the image has keep their placement."""
    if ndim >= 3 or abs(np.linalg.det(affine[:3, :3])) > 0:
        return affine
    u = np.linalg.svd(affine[:3, :ndim], full_matrices=True)[0]   # (3, 3)
    out = affine.copy()
    out[:3, ndim:3] = u[:, ndim:]
    return out


def load_npy(path, *, mmap_mode: Literal["r"] | None = None) -> np.ndarray:
    """``numpy.load`` of a ``.npy`` array of numbers (no pickles), with refusals that say
    what the file is: not a ``.npy`` file at all, or an array of Python objects.

    Parameters
    ----------
    path : str or Path
        The file.
    mmap_mode : {None, "r"}
        As ``numpy.load``.

    Returns
    -------
    ndarray (or memmap) of numbers

    Raises
    ------
    ValueError
        A file without numpy's ``.npy`` header (text, another format renamed), an object
        array, or a damaged file.
    """
    from numpy.lib import format as npy

    p = Path(path)
    with open(p, "rb") as fh:
        if fh.read(len(_NPY_MAGIC)) != _NPY_MAGIC:
            raise Refused(f"{p.name} is not a .npy file (it does not begin with numpy's "
                          ".npy header); give an array saved with numpy.save, or name the "
                          "file by its real format.")
        fh.seek(0)
        read_header = {(1, 0): npy.read_array_header_1_0,
                       (2, 0): npy.read_array_header_2_0}.get(npy.read_magic(fh))
        dtype = read_header(fh)[2] if read_header else None
    if dtype is not None and dtype.hasobject:
        raise Refused(f"{p.name} holds Python objects (dtype {dtype}), not numbers; save the "
                      "image or labels as an array of integers or floats with numpy.save.")
    return np.load(p, mmap_mode=mmap_mode, allow_pickle=False)


_NPY_MAGIC = b"\x93NUMPY"
