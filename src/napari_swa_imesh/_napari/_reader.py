"""Reader for NIfTI volumes (.nii, .nii.gz) that keeps the voxel spacing as the layer scale."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

__all__ = ["get_nifti_reader", "read_nifti"]


def get_nifti_reader(path) -> Callable | None:
    """npe2 reader command: a reader for one NIfTI file, else None."""
    if isinstance(path, (list, tuple)) or not str(path).lower().endswith((".nii", ".nii.gz")):
        return None
    return read_nifti


def read_nifti(path) -> list[tuple]:
    """Read a NIfTI file as an image layer whose ``scale`` is the voxel spacing."""
    from ..io import read_image

    image, spacing = read_image(path)
    name = Path(str(path)).name
    for suffix in (".gz", ".nii"):
        name = name.removesuffix(suffix)
    return [(image, {"name": name, "scale": spacing}, "image")]
