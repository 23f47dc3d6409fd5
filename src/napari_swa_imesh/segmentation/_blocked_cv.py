"""Spatially blocked cross-validation of the recommended method's levels.

The pixel CV (``eps_l``) splits sampled pixels of the boxes at random: neighbours of a test
pixel are in the training set and window statistics overlap, so it is optimistic. Here the
folds are whole blocks: every box is cut in two halves across its longest side, fold 0
holds the first halves and fold 1 the second, and the features of each half are computed
on that half alone (no window sees the other fold). A classifier trained on one fold
labels the other; the error is the percentage of the test pixels it gets wrong, with as
many test pixels per material (up to ``per_material``), so a large material does not hide
a small one.
"""

from __future__ import annotations

import numpy as np

from ._classifiers import GaussianClassifier
from ._samples import Samples
from ._window_features import feature_levels, multiscale_features

__all__ = ["blocked_cv_errors", "BLOCKED_CV_METHOD"]

BLOCKED_CV_METHOD = ("2-fold cross-validation over halves of the sample boxes (each box cut "
                     "across its longest side; features of a half computed on it alone)")


def _halves(box) -> tuple[tuple[slice, ...], tuple[slice, ...]] | None:
    """The two halves of a box across its longest side (None for a 1-px-thick box)."""
    sides = [b - a for a, b in zip(box.start, box.stop)]
    axis = int(np.argmax(sides))
    if sides[axis] < 2:
        return None
    mid = box.start[axis] + sides[axis] // 2
    first, second = list(box.slices), list(box.slices)
    first[axis] = slice(box.start[axis], mid)
    second[axis] = slice(mid, box.stop[axis])
    return tuple(first), tuple(second)


def blocked_cv_errors(image: np.ndarray, samples: Samples, top: int, *,
                      per_material: int = 20000, seed: int = 0, coherence: bool = True
                      ) -> dict[int, float] | None:
    """Blocked 2-fold CV error (percent) of the GM classifier of every level 0..`top`.

    Parameters
    ----------
    image : (M, N[, P]) ndarray of float32, or :class:`~._samples.BoxCrops`
        The standardised (and bias-corrected) image the model was fitted on (only its
        sample boxes are read).
    samples : Samples
    top : int
        Largest level.
    per_material : int
        Pixels per material and fold used to train and to test (all, if fewer).
    seed : int
    coherence : bool
        Whether the model uses the coherence features (see :func:`multiscale_features`).

    Returns
    -------
    dict of int to float, or None
        Error per level; None when some material has no box that can be halved (every
        box of it is 1 px thick), so one fold would lack it.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = np.concatenate([rng.normal(0, 1, (32, 16)), rng.normal(5, 1, (32, 16))], 1)
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [32, 16]},
    ...                                  {"label": 2, "start": [0, 16], "stop": [32, 32]}]})
    >>> blocked_cv_errors(img.astype(np.float32), s, 1)[0] < 5
    True
    """
    rng = np.random.default_rng(seed)
    folds: list[tuple[list, list]] = [([], []), ([], [])]
    names: list[str] = []
    for label in samples.labels:
        parts: list[list[np.ndarray]] = [[], []]
        for box in samples.boxes_of(label):
            halves = _halves(box)
            if halves is None:
                continue
            for f, sl in enumerate(halves):
                feats, names = multiscale_features(image[sl], top, coherence)
                parts[f].append(feats.reshape(-1, feats.shape[-1]))
        if not parts[0]:
            return None
        for f in (0, 1):
            rows = np.concatenate(parts[f])
            take = rng.choice(rows.shape[0], min(per_material, rows.shape[0]), replace=False)
            folds[f][0].append(rows[take])
            folds[f][1].append(np.full(take.size, label, np.int64))
    data = [(np.concatenate(X).astype(np.float64), np.concatenate(y)) for X, y in folds]
    levels = feature_levels(names)
    errors = {}
    for j in range(top + 1):
        cols = np.flatnonzero(levels <= j)
        wrong = total = 0
        for f in (0, 1):
            (Xa, ya), (Xb, yb) = data[f], data[1 - f]
            clf = GaussianClassifier(priors="equal").fit(Xa[:, cols], ya)
            wrong += int(np.sum(clf.predict(Xb[:, cols]) != yb))
            total += yb.size
        errors[j] = 100.0 * wrong / total
    return errors
