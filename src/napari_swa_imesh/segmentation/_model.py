"""The reference's model: a classifier of tiles at one scale and feature set (ch. 2).

Its file layout (``param_*`` arrays, ``classifier_options``) is described with the format in
:mod:`._model_io`.
"""

from __future__ import annotations

import numpy as np

from .._validation import label_dtype
from ._classifiers import leave_one_out_error, make_classifier
from ._features import feature_stack, n_features
from ._model_base import SegmentationModel
from ._samples import Material, Samples
from ._tiles import upsample_tiles

__all__ = ["SWAModel", "training_tiles", "check_scale"]


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
    rows, labels = [], []
    names: list[str] = []
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


class SWAModel(SegmentationModel):
    """Classifier of tiles at one scale, fitted on sample boxes.

    Parameters
    ----------
    scale : int
        Tile scale j: tiles of 2^j pixels per axis, each gets one label (the full-resolution
        labels repeat it). Sieving (``segment(..., sieve=n)``) then counts tiles.
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

    def fit(self, image, samples: Samples, *, spacing=None, check_input: bool = True
            ) -> SWAModel:
        """Fit on the full tiles inside the sample boxes and score with leave-one-out.

        Parameters
        ----------
        image : (M, N[, P]) array_like
        samples : Samples
        spacing : sequence of float, optional
            Recorded in the model.
        check_input : bool
            False: `samples` were checked against the float `image` (see
            :mod:`._model_base`).
        """
        img = self.checked_training_image(image, samples, check_input)
        check_scale(self.scale, img.shape)
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

    def predict(self, image, *, check_input: bool = True) -> np.ndarray:
        """Full-resolution labels: every pixel takes its tile's label (the image's shape)."""
        img = self.checked_image(image, check_input)
        return upsample_tiles(self.predict_tiles(img, check_input=False), self.scale,
                              img.shape)

    def predict_tiles(self, image, *, check_input: bool = True) -> np.ndarray:
        """Label of every tile of `image` (tile grid from index 0; last tiles may be partial).

        Returns
        -------
        (ceil(M/2^j), ceil(N/2^j)[, ...]) ndarray of int32
        """
        feats, _ = self.tile_features(image, check_input=check_input)
        return self.classify_features(feats)

    def tile_features(self, image, *, check_input: bool = True
                      ) -> tuple[np.ndarray, np.ndarray]:
        """The model's feature set on every tile of `image`: (features, valid pixel counts)."""
        img = self.checked_image(image, check_input)
        img = np.asarray(img, np.float64)      # the feature workers compute in place
        check_scale(self.scale, img.shape)
        feats, counts, _ = feature_stack(img, self.scale, self.feature_set)
        return feats, counts

    def classify_features(self, feats: np.ndarray) -> np.ndarray:
        """Labels (int32, int64 for labels >= 2^31; tile grid shape) of tile features from
        :meth:`tile_features`.
        """
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

    # -- file format ----------------------------------------------------------------------
    def file_content(self) -> tuple[dict, dict[str, np.ndarray]]:
        """The JSON ``meta`` and the arrays :meth:`save` writes."""
        meta = {**self._common_meta(), "scale": self.scale,
                "feature_set": self.feature_set, "feature_names": self.feature_names,
                "classifier": self.classifier_name, "scores": self.scores,
                "classifier_options": self.classifier.get_params()}
        arrays = {f"param_{k}": v for k, v in self.classifier.fitted_arrays().items()}
        return meta, arrays

    @classmethod
    def from_file_content(cls, meta: dict, arrays: dict[str, np.ndarray]) -> SWAModel:
        """Rebuild from the ``meta`` dict and arrays of a saved file."""
        model = cls(scale=meta["scale"], feature_set=meta["feature_set"],
                    classifier=meta["classifier"])
        model.classifier.set_params(**meta.get("classifier_options", {}))
        model.classifier.set_fitted({k[len("param_"):]: v for k, v in arrays.items()
                                     if k.startswith("param_")})
        model._restore_common(meta)
        model.feature_names = list(meta["feature_names"])
        model.scores = meta.get("scores", {})
        return model


def check_scale(scale: int, shape: tuple[int, ...]) -> None:
    """Raise ValueError unless tiles of 2^scale px fit an image of `shape`."""
    top = int(np.floor(np.log2(max(shape))))
    if not 0 <= scale <= top:
        raise ValueError(
            f"scale {scale} does not fit an image of shape {shape}: choose 0..{top} "
            f"(tiles of 1..{1 << top} px)."
        )
