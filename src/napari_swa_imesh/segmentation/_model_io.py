"""The model file, and :func:`load_model` for both models.

Format (``.npz``, no pickles): arrays under their own names plus ``meta``, a JSON string
with ``format`` ("swa-imesh-model"), ``format_version`` (:data:`MODEL_FORMAT_VERSION`, the
layout), ``version`` (of the package that wrote it), ``method``, ``scale``,
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
one ValueError that says so, and checks the format version: a newer format than this
package reads is refused with one sentence (update napari-swa-imesh); a format 0 file
(written before the number existed, when absent keys meant defaults) is brought to format 1
by :func:`_upgrade` before either model reads it. A saved model applies to any image of the
same dimensionality.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from .. import __version__
from ._model import SWAModel
from ._model_base import MODEL_FORMAT, MODEL_FORMAT_VERSION, check_model_path, write_model_to
from ._recommended import RECOMMENDED_METHOD, RecommendedModel

__all__ = ["MODEL_FORMAT", "MODEL_FORMAT_VERSION", "check_model_path", "write_model_to",
           "read_model_file", "load_model", "MODELS"]

MODELS: dict[str, type[SWAModel] | type[RecommendedModel]] = {
    "reference": SWAModel, RECOMMENDED_METHOD: RecommendedModel}


def read_model_file(path) -> tuple[dict, dict[str, np.ndarray]]:
    """The ``meta`` dict and the arrays of a model file.

    Raises
    ------
    FileNotFoundError
        No file at `path`.
    ValueError
        The file is not a complete swa-imesh model file, or its format is newer than this
        package reads.
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
    fmt = meta.get("format_version", 0)
    if not isinstance(fmt, int) or isinstance(fmt, bool) or fmt < 0:
        raise ValueError(f"{bad} (format_version {fmt!r} is not a whole number).")
    if fmt > MODEL_FORMAT_VERSION:
        raise ValueError(
            f"{p} is a model file of format {fmt} (written by napari-swa-imesh "
            f"{meta.get('version', '?')}), newer than this napari-swa-imesh {__version__} "
            f"reads (format {MODEL_FORMAT_VERSION}); update napari-swa-imesh.")
    return _upgrade(meta), arrays


def _upgrade(meta: dict) -> dict:
    """`meta` in the current format: a format 0 file gets the values its absence meant."""
    if meta.get("format_version", 0) == 0:
        meta = {"method": "reference", **meta, "format_version": MODEL_FORMAT_VERSION}
        if meta["method"] == RECOMMENDED_METHOD:
            # saved before the coherence features and the intensity standardisation
            meta = {"coherence": False, "intensity": {"offset": 0.0, "scale": 1.0}, **meta}
    return meta


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
        As the file's ``method`` says (format 0 files without one are reference models).

    Raises
    ------
    FileNotFoundError
        No file at `path`.
    ValueError
        A damaged file, or a method this version does not know.
    """
    meta, arrays = read_model_file(path)
    p = Path(path)
    method = meta.get("method")
    if not isinstance(method, str):
        raise ValueError(f"{p} is a damaged or incomplete swa-imesh model file (no method); "
                         "save the model again.")
    if method not in MODELS:
        raise ValueError(f"{p} holds a model of method {method!r}, which this version does "
                         "not know; update napari-swa-imesh.")
    try:
        return MODELS[method].from_file_content(meta, arrays)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise ValueError(f"{p} is a damaged or incomplete swa-imesh model file "
                         f"({type(exc).__name__}: {exc}); save the model again.") from exc
