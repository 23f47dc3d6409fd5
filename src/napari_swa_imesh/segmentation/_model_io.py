"""The model file, and :func:`load_model` for both models.

Format (``.npz``, no pickles): arrays under their own names plus ``meta``, a JSON string
with ``format`` ("swa-imesh-model"), ``version`` (of this package), ``method``, ``scale``,
``feature_set``, ``feature_names``, ``classifier``, ``ndim``, ``materials`` (label, name,
colour), ``spacing`` (units of the training image) and the training ``scores``.

* ``method`` absent or "reference": :class:`~._model.SWAModel`; the arrays are the fitted
  classifier's (``param_*``) and ``classifier_options`` its constructor parameters.
* ``method`` "recommended": :class:`~._recommended.RecommendedModel`; one Gaussian
  classifier per scale j (arrays ``level{j}_*``), and its ``options``, ``class_means``,
  ``level_error``, ``intensity`` (offset and scale of the standardisation) and
  ``fisher`` ratios.

Both are written by :meth:`~._model_base.SegmentationModel.save` (through
:func:`~napari_swa_imesh.io.atomic_write`); every file is read by :func:`read_model_file`,
which turns any damage (truncation, random bytes, a ``meta`` that is not an object) into
one ValueError that says so. A saved model applies to any image of the same
dimensionality.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ._model import SWAModel
from ._model_base import MODEL_FORMAT, check_model_path, write_model_to
from ._recommended import RECOMMENDED_METHOD, RecommendedModel

__all__ = ["MODEL_FORMAT", "check_model_path", "write_model_to", "read_model_file",
           "load_model", "MODELS"]

MODELS = {"reference": SWAModel, RECOMMENDED_METHOD: RecommendedModel}


def read_model_file(path) -> tuple[dict, dict[str, np.ndarray]]:
    """The ``meta`` dict and the arrays of a model file.

    Raises
    ------
    FileNotFoundError
        No file at `path`.
    ValueError
        The file is not a complete swa-imesh model file.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no model file at {p}; check the path.")
    bad = (f"{p} is not a swa-imesh model file (or it is damaged); give a file written by "
           "`swa-imesh segment --model-out` or the plugin's Save model")
    if not zipfile.is_zipfile(p):
        raise ValueError(bad + ".")
    try:
        with np.load(p, allow_pickle=False) as data:
            if "meta" not in data.files:
                raise ValueError("no meta entry")
            meta = json.loads(str(data["meta"]))
            arrays = {k: data[k] for k in data.files if k != "meta"}
    except Exception as exc:  # zip, zlib, npy header and JSON errors all mean "damaged"
        raise ValueError(f"{bad} ({type(exc).__name__}).") from exc
    if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
        raise ValueError(bad + ".")
    return meta, arrays


def load_model(path) -> SWAModel | RecommendedModel:
    """Read a model written by ``save`` (either model) or ``swa-imesh segment --model-out``.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` model file (arrays and a JSON ``meta`` entry; pickles are never
        loaded).

    Returns
    -------
    SWAModel or RecommendedModel
        As the file's ``method`` says (files without one are reference models).

    Raises
    ------
    FileNotFoundError
        No file at `path`.
    ValueError
        A damaged file, or a method this version does not know.
    """
    meta, arrays = read_model_file(path)
    p = Path(path)
    method = meta.get("method", "reference")
    if method not in MODELS:
        raise ValueError(f"{p} holds a model of method {method!r}, which this version does "
                         "not know; update napari-swa-imesh.")
    try:
        return MODELS[method].from_file_content(meta, arrays)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise ValueError(f"{p} is a damaged or incomplete swa-imesh model file "
                         f"({type(exc).__name__}: {exc}); save the model again.") from exc
