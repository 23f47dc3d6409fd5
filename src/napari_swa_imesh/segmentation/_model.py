"""A fitted SWA classifier at one scale and feature set, and its file format.

File format (``.npz``, no pickles): every fitted classifier array under its own name,
plus ``meta``, a JSON string with ``format`` ("swa-imesh-model"), ``version`` (of this
package), ``scale``, ``feature_set``, ``feature_names``, ``classifier``, ``ndim``,
``materials`` (label, name, colour), ``spacing`` (units of the training image) and the
training scores (``eps_l``, ``eps_m``, tiles per material). Load it with
:func:`load_model`; it applies to any image of the same dimensionality.

A ``method`` entry in ``meta`` says which model wrote the file: absent or "reference" for
:class:`SWAModel`, "recommended" for
:class:`~napari_swa_imesh.segmentation._recommended.RecommendedModel` (its arrays are
``level{j}_*``, one Gaussian classifier per scale). Older files have no ``method`` and
load as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._validation import as_image, label_dtype
from ..io import atomic_write
from ._classifiers import LVQClassifier, leave_one_out_error, make_classifier
from ._features import feature_stack, n_features
from ._model_io import MODEL_FORMAT, check_model_path, read_model_file, write_model_to
from ._samples import Material, Samples, check_contrast

__all__ = ["SWAModel", "load_model", "training_tiles", "MODEL_FORMAT"]



def training_tiles(image: np.ndarray, samples: Samples, scale: int, feature_set: str
                   ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Feature rows of the full tiles inside every sample box (tiles aligned to each box).

    Returns
    -------
    X : (n, n_features) ndarray of float64
    y : (n,) ndarray of int64
        Material label of each row.
    names : list of str
        Feature names.

    Raises
    ------
    ValueError
        If a material has fewer than two full tiles at `scale`.
    """
    d = image.ndim
    full = 1 << (scale * d)
    rows, labels, names = [], [], None
    for label in samples.labels:
        got = 0
        for box in samples.boxes_of(label):
            crop = image[box.slices]
            if min(crop.shape) < (1 << scale):
                continue
            feats, counts, names = feature_stack(crop, scale, feature_set)
            keep = counts == full
            rows.append(feats[keep])
            got += int(keep.sum())
        if got < 2:
            side = 1 << scale
            raise ValueError(
                f"material {samples.name_of(label)!r} (label {label}) has {got} full tile(s) "
                f"of {side} px per axis at scale {scale} inside its sample boxes; at least 2 "
                f"are needed. Draw larger boxes (at least {2 * side} px along one axis and "
                f"{side} px along the others) or choose a smaller scale."
            )
        labels.append(np.full(got, label, np.int64))
    X = np.concatenate(rows)
    if not np.isfinite(X).all():
        raise ValueError(
            f"some {feature_set} features of the training tiles are not finite at scale "
            f"{scale}; choose another scale or feature set."
        )
    return X, np.concatenate(labels), list(names)


class SWAModel:
    """Classifier of tiles at one scale, fitted on sample boxes.

    Parameters
    ----------
    scale : int
        Tile scale j (tiles of 2^j pixels per axis).
    feature_set : {"F1", ..., "F7"}
        Feature set of Table 2.1 (F1 = moments, the reference's choice).
    classifier : {"gm", "md", "lvq"}
        Gaussian maximum likelihood (default), minimum distance or LVQ.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(0, 3, (32, 16))], 1)
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [32, 16]},
    ...                                  {"label": 2, "start": [0, 16], "stop": [32, 32]}]})
    >>> m = SWAModel(scale=2).fit(img, s)
    >>> m.predict_tiles(img).shape
    (8, 8)
    """

    def __init__(self, *, scale: int, feature_set: str = "F1", classifier: str = "gm"):
        self.scale = int(scale)
        self.feature_set = str(feature_set).upper()
        self.classifier_name = str(classifier).lower()
        self.classifier = make_classifier(self.classifier_name)
        self.materials: list[Material] = []
        self.feature_names: list[str] = []
        self.ndim: int | None = None
        self.spacing: tuple[float, ...] | None = None
        self.scores: dict = {}

    @property
    def labels(self) -> list[int]:
        return [m.label for m in self.materials]

    def fit(self, image, samples: Samples, *, spacing=None) -> "SWAModel":
        """Fit on the full tiles inside the sample boxes and score with leave-one-out."""
        img = as_image(image)
        samples.check(img.shape)
        check_contrast(img, samples)
        _check_scale(self.scale, img.shape)
        n_features(self.feature_set, img.ndim, self.scale)  # validates the set name
        X, y, names = training_tiles(img, samples, self.scale, self.feature_set)
        self.classifier.fit(X, y)
        eps_l, how = leave_one_out_error(self.classifier, X, y)
        self.materials = list(samples.materials)
        self.feature_names = names
        self.ndim = img.ndim
        self.spacing = None if spacing is None else tuple(float(s) for s in spacing)
        self.scores = {
            "eps_l": eps_l, "eps_l_method": how,
            "eps_m": -len(names) * eps_l / 100.0,
            "training_tiles": {int(m): int(np.sum(y == m)) for m in samples.labels},
            "regularized": [int(c) for c, r in zip(
                self.classifier.classes_, getattr(self.classifier, "regularized_", []))
                if r],
        }
        return self

    def predict_tiles(self, image) -> np.ndarray:
        """Label of every tile of `image` (tile grid from index 0; last tiles may be partial).

        Returns
        -------
        (ceil(M/2^j), ceil(N/2^j)[, ...]) ndarray of int32
        """
        feats, _ = self.tile_features(image)
        return self.classify_features(feats)

    def tile_features(self, image) -> tuple[np.ndarray, np.ndarray]:
        """The model's feature set on every tile of `image`: (features, valid pixel counts)."""
        if not self.materials:
            raise ValueError("this model is not fitted; call fit() or load a saved model.")
        img = as_image(image)
        if img.ndim != self.ndim:
            raise ValueError(
                f"the model was fitted on {self.ndim}-D images; got a {img.ndim}-D image."
            )
        check_contrast(img)
        _check_scale(self.scale, img.shape)
        feats, counts, _ = feature_stack(img, self.scale, self.feature_set)
        return feats, counts

    def classify_features(self, feats: np.ndarray) -> np.ndarray:
        """Labels (int32, int64 for labels >= 2^31; tile grid shape) of tile features from :meth:`tile_features`."""
        tiles = feats.reshape(-1, feats.shape[-1])
        # partial tiles at the far edge get features from their valid pixels; a non-finite
        # feature (e.g. a one-pixel sliver's skewness) is replaced by the training mean so
        # that the tile is still classified by its other features
        bad = ~np.isfinite(tiles)
        if bad.any():
            tiles = tiles.copy()
            tiles[bad] = np.broadcast_to(self.classifier.offset_, tiles.shape)[bad]
        labels = self.classifier.predict(tiles).reshape(feats.shape[:-1])
        return labels.astype(label_dtype(self.labels))

    # -- file format -------------------------------------------------------------------
    def save(self, path, *, force: bool = False) -> Path:
        """Write the model as NPZ + JSON metadata (no pickle); see the module docstring."""
        check_model_path(path)
        with atomic_write([path], force=force) as (tmp,):
            write_model_to(tmp, *self.file_content())
        return Path(path)

    def file_content(self) -> tuple[dict, dict[str, np.ndarray]]:
        """The JSON ``meta`` and the arrays :meth:`save` writes."""
        from .. import __version__

        meta = {
            "version": __version__, "scale": self.scale,
            "feature_set": self.feature_set, "feature_names": self.feature_names,
            "classifier": self.classifier_name, "ndim": self.ndim, "spacing": self.spacing,
            "materials": [{"label": m.label, "name": m.name, "color": m.color}
                          for m in self.materials],
            "scores": self.scores,
            "classifier_options": {k: v for k, v in vars(self.classifier).items()
                                   if not k.endswith("_") and not k.startswith("_")},
        }
        arrays = {f"param_{k}": v for k, v in self.classifier.get_params().items()}
        return meta, arrays


def load_model(path):
    """Read a model written by :meth:`SWAModel.save` or :meth:`RecommendedModel.save`.

    Returns
    -------
    SWAModel or RecommendedModel
        As the file's ``method`` says (files without one are reference models).
    """
    meta, arrays = read_model_file(path)
    p = Path(path)
    try:
        return _model_from_file(meta, arrays, p)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise ValueError(f"{p} is a damaged or incomplete swa-imesh model file "
                         f"({type(exc).__name__}: {exc}); save the model again.") from exc


def _model_from_file(meta: dict, arrays: dict, p: Path):
    method = meta.get("method", "reference")
    if method == "recommended":
        from ._recommended import RecommendedModel

        return RecommendedModel.from_saved(meta, arrays)
    if method != "reference":
        raise ValueError(f"{p} holds a model of method {method!r}, which this version does "
                         "not know; update napari-swa-imesh.")
    params = {k[len("param_"):]: v for k, v in arrays.items() if k.startswith("param_")}
    model = SWAModel(scale=meta["scale"], feature_set=meta["feature_set"],
                     classifier=meta["classifier"])
    for k, v in meta.get("classifier_options", {}).items():
        setattr(model.classifier, k, v)
    model.classifier.set_params(params)
    model.materials = [Material(int(m["label"]), m["name"], m.get("color"))
                       for m in meta["materials"]]
    model.feature_names = list(meta["feature_names"])
    model.ndim = int(meta["ndim"])
    model.spacing = tuple(meta["spacing"]) if meta.get("spacing") else None
    model.scores = meta.get("scores", {})
    return model


def _check_scale(scale: int, shape: tuple[int, ...]) -> None:
    top = int(np.floor(np.log2(max(shape))))
    if not 0 <= scale <= top:
        raise ValueError(
            f"scale {scale} does not fit an image of shape {shape}: choose 0..{top} "
            f"(tiles of 1..{1 << top} px)."
        )
