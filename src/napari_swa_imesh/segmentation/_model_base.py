"""What both segmentation models share: the interface, the image check, and ``save``.

A model (:class:`~._model.SWAModel`, the reference; :class:`~._recommended.RecommendedModel`)
is fitted state with scikit-learn's shape:

* ``fit(image, samples, *, spacing=None, check_input=True)`` -> the model;
* ``predict(image, *, check_input=True)`` -> full-resolution labels (the image's shape);
* ``predict_tiles(image)`` -> one label per tile at :attr:`scale`;
* ``save(path, *, force=False)`` -> the path (written here, once, for both);
* ``file_content()`` -> ``(meta, arrays)`` and ``from_file_content(meta, arrays)``, the
  model's part of the file format of :mod:`._model_io`.

``check_input=False`` skips the image checks for callers that made them already
(:func:`~._segment.segment` checks once at its door); as in scikit-learn, wrong input then
gives a wrong result instead of an error.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .._validation import IMAGE_NDIM, as_image, label_dtype
from ..io import atomic_write
from ._samples import Material, check_contrast

__all__ = ["SegmentationModel", "MODEL_FORMAT", "MODEL_FORMAT_VERSION", "check_model_path",
           "write_model_to"]

MODEL_FORMAT = "swa-imesh-model"
#: the layout of ``meta`` and the arrays; raise it when a reader of the previous layout
#: would misread a new file (files written before the number existed are format 0)
MODEL_FORMAT_VERSION = 1


def check_model_path(path) -> None:
    """Raise ValueError unless `path` names a model file (``.npz``)."""
    if Path(path).suffix.lower() != ".npz":
        raise ValueError(f"model files end in .npz; got {Path(path).name}.")


def write_model_to(tmp, meta: dict, arrays: dict[str, Any]) -> None:
    """Write `meta` (JSON, with the format tag and version) and `arrays` to the path `tmp`."""
    meta = {"format": MODEL_FORMAT, "format_version": MODEL_FORMAT_VERSION,
            "version": __version__, **meta}
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)


class SegmentationModel:
    """Base of the two models: fitted materials, the image check and the file writer."""

    method = "reference"
    materials: list[Material]
    ndim: int | None
    spacing: tuple[float, ...] | None

    @property
    def labels(self) -> list[int]:
        """Material labels in the order the samples list them."""
        return [m.label for m in self.materials]

    def label_values(self) -> np.ndarray:
        """Material labels in :attr:`labels` order, in a dtype that holds them."""
        return np.asarray(self.labels, label_dtype(self.labels))

    def checked_image(self, image, check_input: bool = True) -> np.ndarray:
        """`image` checked for this fitted model (no copy of float input).

        Raises
        ------
        ValueError
            If the model is not fitted, the dimensionality differs from the training
            image's, or the image has nothing to segment.
        """
        if not self.materials:
            raise ValueError("this model is not fitted; call fit() or load a saved model.")
        if not check_input:
            return image
        img = as_image(image, max_ndim=IMAGE_NDIM[-1], copy=False)
        if img.ndim != self.ndim:
            raise ValueError(
                f"the model was fitted on {self.ndim}-D images; got a {img.ndim}-D image.")
        check_contrast(img)
        return img

    @staticmethod
    def checked_training_image(image, samples, check_input: bool = True) -> np.ndarray:
        """`image` checked for fitting on `samples` (no copy of float input): a real
        single-channel image that holds every box and some contrast in them.
        """
        if not check_input:
            return image
        img = as_image(image, max_ndim=IMAGE_NDIM[-1], copy=False)
        samples.check(img.shape)
        check_contrast(img, samples)
        return img

    def _common_meta(self) -> dict:
        """The ``meta`` entries both models write."""
        return {"version": __version__, "method": self.method, "ndim": self.ndim,
                "spacing": self.spacing,
                "materials": [{"label": m.label, "name": m.name, "color": m.color}
                              for m in self.materials]}

    def _restore_common(self, meta: dict) -> None:
        self.materials = [Material(int(m["label"]), m["name"], m.get("color"))
                          for m in meta["materials"]]
        self.ndim = int(meta["ndim"])
        self.spacing = tuple(meta["spacing"]) if meta.get("spacing") else None

    def file_content(self) -> tuple[dict, dict[str, np.ndarray]]:
        """The JSON ``meta`` and the arrays :meth:`save` writes (see :mod:`._model_io`)."""
        raise NotImplementedError

    def save(self, path, *, force: bool = False) -> Path:
        """Write the model as NPZ arrays + JSON ``meta`` (no pickles; see :mod:`._model_io`).

        Parameters
        ----------
        path : str or Path
            Ends in ``.npz``.
        force : bool
            Replace an existing file.
        """
        check_model_path(path)
        with atomic_write([path], force=force) as (tmp,):
            write_model_to(tmp, *self.file_content())
        return Path(path)
