"""The model file: NPZ arrays plus one JSON ``meta`` entry, no pickles.

Both models (:class:`~._model.SWAModel`, :class:`~._recommended.RecommendedModel`) write
through :func:`write_model_to` inside :func:`~napari_swa_imesh.io.atomic_write`, and
every file is read through :func:`read_model_file`, which turns any damage (truncation,
random bytes, a ``meta`` that is not an object) into one ValueError that says so.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["MODEL_FORMAT", "check_model_path", "write_model_to", "read_model_file"]

MODEL_FORMAT = "swa-imesh-model"


def check_model_path(path) -> None:
    """Raise ValueError unless `path` names a model file (``.npz``)."""
    if Path(path).suffix.lower() != ".npz":
        raise ValueError(f"model files end in .npz; got {Path(path).name}.")


def write_model_to(tmp, meta: dict, arrays: dict[str, np.ndarray]) -> None:
    """Write `meta` (JSON) and `arrays` to the temporary path `tmp`."""
    meta = {"format": MODEL_FORMAT, **meta}
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)


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
