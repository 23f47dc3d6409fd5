"""Tile classifiers of the reference (sec. 2.4.1.4): GM, MD and LVQ, with leave-one-out error.

All three share scikit-learn's shape: ``fit(X, y)`` then ``predict(X)``, with ``X`` of
shape (n_tiles, n_features). Features are standardised with the training set's mean and
standard deviation before use (moments differ by orders of magnitude), and the
classifiers store their parameters as plain arrays so a model saves to NPZ/JSON.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["GaussianClassifier", "MinimumDistanceClassifier", "LVQClassifier",
           "make_classifier", "leave_one_out_error", "CLASSIFIERS", "PREDICT_BATCH"]

CLASSIFIERS = ("gm", "md", "lvq")
PREDICT_BATCH = 1 << 19  # rows per prediction batch: bounds the temporary memory


class _Standardised:
    """Feature standardisation shared by the classifiers."""

    classes_: np.ndarray
    offset_: np.ndarray
    scale_: np.ndarray

    def _fit_scaler(self, X: np.ndarray) -> np.ndarray:
        self.offset_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        return (X - self.offset_) / self.scale_

    def _scaled(self, X: np.ndarray) -> np.ndarray:
        return (X - self.offset_) / self.scale_

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Predict a class label for every row of `X` (in batches, to bound memory)."""
        X = np.asarray(X, dtype=np.float64)
        out = np.empty(X.shape[0], dtype=self.classes_.dtype)
        for i in range(0, X.shape[0], PREDICT_BATCH):
            rows = X[i:i + PREDICT_BATCH]
            out[i:i + PREDICT_BATCH] = self.classes_[self._predict_index(self._scaled(rows))]
        return out

    def get_params(self) -> dict:
        """Constructor parameters (scikit-learn's convention: no fitted state)."""
        return {k: v for k, v in vars(self).items()
                if not k.endswith("_") and not k.startswith("_")}

    def set_params(self, **params):
        """Set constructor parameters; returns the classifier."""
        for k, v in params.items():
            if k not in self.get_params():
                raise ValueError(f"{type(self).__name__} has no parameter {k!r}; it has "
                                 f"{', '.join(self.get_params()) or 'none'}.")
            setattr(self, k, v)
        return self

    def fitted_arrays(self) -> dict[str, np.ndarray]:
        """The fitted state as plain arrays (what a model file stores)."""
        return {k: v for k, v in vars(self).items() if k.endswith("_")}

    def set_fitted(self, arrays: dict[str, np.ndarray]):
        """Restore the fitted state from :meth:`fitted_arrays`; returns the classifier."""
        for k, v in arrays.items():
            setattr(self, k, np.asarray(v))
        self._restore()
        return self

    def _restore(self) -> None:
        """Rebuild derived state after :meth:`set_fitted` (nothing by default)."""


def _check_training(X, y):
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"X must be (n_tiles, n_features) with one label per row; got "
                         f"X {X.shape}, y {y.shape}.")
    if not np.isfinite(X).all():
        raise ValueError("training features contain NaN or infinity; check the sample boxes "
                         "lie on image pixels.")
    classes, counts = np.unique(y, return_counts=True)
    if classes.size < 2:
        raise ValueError(f"need at least two materials to classify; got {classes.tolist()}.")
    if counts.min() < 2:
        bad = classes[counts < 2].tolist()
        raise ValueError(
            f"material(s) {bad} have fewer than 2 training tiles; draw larger sample boxes "
            "or choose a smaller scale."
        )
    return X, y, classes, counts


class GaussianClassifier(_Standardised):
    """Gaussian maximum likelihood with class priors n_i/n (quadratic discriminant, eq. 2.30).

    Parameters
    ----------
    priors : {"proportional", "equal"}
        ``"proportional"``: n_i/n, the reference's eq. 2.30 (the training set's class
        frequencies). ``"equal"``: 1/K, for training sets whose class sizes say nothing
        about the image (sample boxes drawn by hand).
    shrinkage : float
        Ridge added to every class covariance, as a fraction of its mean eigenvalue.
        Covariances of constant or few tiles are singular; a tiny ridge keeps them
        invertible and barely moves a well-conditioned one. ``regularized_`` records the
        classes where it mattered (condition number above 1e8 before the ridge).
    """

    name = "gm"

    def __init__(self, shrinkage: float = 1e-6, priors: str = "proportional"):
        if priors not in ("proportional", "equal"):
            raise ValueError(f"priors must be 'proportional' or 'equal'; got {priors!r}.")
        self.shrinkage = float(shrinkage)
        self.priors = priors

    def fit(self, X, y) -> GaussianClassifier:
        X, y, classes, counts = _check_training(X, y)
        Z = self._fit_scaler(X)
        self.classes_ = classes
        self.priors_ = (counts / counts.sum() if self.priors == "proportional"
                        else np.full(classes.size, 1.0 / classes.size))
        self.means_ = np.stack([Z[y == c].mean(axis=0) for c in classes])
        covs = []
        for c in classes:
            zc = Z[y == c] - Z[y == c].mean(axis=0)
            cov = zc.T @ zc / zc.shape[0]
            covs.append(cov)
        covs = np.stack(covs)
        self.covariances_, self.regularized_ = _regularise(covs, self.shrinkage)
        self._factor()
        return self

    def _factor(self):
        self.cholesky_ = np.linalg.cholesky(self.covariances_)
        self.logdet_ = 2 * np.log(np.diagonal(self.cholesky_, axis1=1, axis2=2)).sum(axis=1)

    def _restore(self) -> None:
        self._factor()

    def log_likelihood(self, X, *, dtype=np.float64, out: np.ndarray | None = None
                       ) -> np.ndarray:
        """Log-likelihood plus log prior of every class for every row (eq. 2.30).

        ``log p_i - 0.5 log det S_i - 0.5 (z - m_i)' S_i^-1 (z - m_i)`` with z the
        standardised row: eq. 2.30's discriminant with the sign turned, without the
        constant ``-p/2 log 2 pi`` that all classes share. The largest value wins.

        Parameters
        ----------
        X : (n, p) array_like of float
            Feature rows (raw units; standardised here). Read in batches, never copied
            whole, so a column-slice view of a larger array costs nothing.
        dtype : {numpy.float64, numpy.float32}
            Precision of the computation; float32 halves memory and time for per-pixel
            use (the inverse Cholesky factors are precomputed, one small matrix product
            per class and batch).
        out : (K, n) ndarray of `dtype`, optional
            Written in place and returned.

        Returns
        -------
        (K, n) ndarray of `dtype`
            Class-first (rows in :attr:`classes_` order): a reduction over K classes is
            then K elementwise passes, fast in numpy.

        Examples
        --------
        >>> clf = GaussianClassifier().fit([[0.0], [0.2], [1.0], [1.2]], [1, 1, 2, 2])
        >>> clf.log_likelihood([[0.1], [1.1]]).argmax(axis=0).tolist()
        [0, 1]
        """
        X = np.asarray(X)
        inv = np.linalg.inv(self.cholesky_).astype(dtype)                 # (K, p, p)
        shift = np.einsum("kij,kj->ki", inv, self.means_).astype(dtype)   # (K, p)
        const = (-0.5 * self.logdet_ + np.log(self.priors_)).astype(dtype)
        offset = self.offset_.astype(dtype)
        scale = (1.0 / self.scale_).astype(dtype)
        if out is None:
            out = np.empty((self.classes_.size, X.shape[0]), dtype)
        for i in range(0, X.shape[0], PREDICT_BATCH):
            z = (X[i:i + PREDICT_BATCH] - offset) * scale                # (b, p)
            for c in range(self.classes_.size):
                w = z @ inv[c].T - shift[c]
                out[c, i:i + PREDICT_BATCH] = const[c] - 0.5 * np.einsum("ij,ij->i", w, w)
        return out

    def predict(self, X) -> np.ndarray:
        """The most likely class of every row of `X` (ties: the first class)."""
        X = np.asarray(X, dtype=np.float64)
        return self.classes_[np.argmax(self.log_likelihood(X), axis=0)]

    def leave_one_out(self, X, y) -> np.ndarray:
        """Exact leave-one-out predictions: each tile classified by a GM fitted without it.

        Only the left-out tile's own class changes, so every tile gets its own class mean
        and covariance (n x p x p arrays, batched linear algebra), the other classes keep
        theirs. The standardisation is kept from the full fit (it is an affine change of
        units that GM is invariant to, up to the ridge).
        """
        X, y, classes, counts = _check_training(X, y)
        Z = self._scaled(X)
        g = -self.log_likelihood(X).T                 # (n, K) discriminants g_i, eq. 2.30
        for i, c in enumerate(classes):
            rows = np.flatnonzero(y == c)
            n = rows.size
            zc = Z[rows]
            mean = zc.mean(axis=0)
            scatter = (zc - mean).T @ (zc - mean)
            d = zc - mean                                   # (n, p)
            mean_wo = (n * mean - zc) / (n - 1)             # (n, p)
            scatter_wo = scatter - (n / (n - 1)) * d[:, :, None] * d[:, None, :]
            cov_wo, _ = _regularise(scatter_wo / (n - 1), self.shrinkage)
            sign, logdet = np.linalg.slogdet(cov_wo)
            r = zc - mean_wo
            maha = np.einsum("np,np->n", r, np.linalg.solve(cov_wo, r[:, :, None])[..., 0])
            proportional = getattr(self, "priors", "proportional") == "proportional"
            prior = (n - 1) / (counts.sum() - 1) if proportional else self.priors_[i]
            g[rows, i] = 0.5 * maha + 0.5 * logdet - np.log(prior)
            others = [k for k in range(classes.size) if k != i]
            if proportional:
                # the other classes' priors change because one tile is gone from the total
                g[np.ix_(rows, others)] += np.log(self.priors_[others]) - np.log(
                    counts[others] / (counts.sum() - 1))
        return classes[np.argmin(g, axis=1)]


def _regularise(covs: np.ndarray, shrinkage: float):
    p = covs.shape[-1]
    tr = np.trace(covs, axis1=-2, axis2=-1) / p
    ridge = shrinkage * np.where(tr > 0, tr, 1.0) + 1e-12
    eig = np.linalg.eigvalsh(covs)
    regularized = eig[..., 0] <= 1e-8 * np.maximum(eig[..., -1], 1e-300)
    out = covs + ridge[..., None, None] * np.eye(p)
    # a class whose tiles are all identical: give it the unit sphere of the pooled units
    flat = tr <= 0
    if np.any(flat):
        out[flat] = np.eye(p) * 1e-6
    return out, regularized


class MinimumDistanceClassifier(_Standardised):
    """Nearest training tile in standardised feature space (K-nn with K = 1, "MD").

    It takes no parameters: :meth:`fit` keeps the standardised training tiles and their
    labels, and :meth:`predict` gives each tile the label of the nearest one.
    """

    name = "md"

    def fit(self, X, y) -> MinimumDistanceClassifier:
        X, y, classes, _ = _check_training(X, y)
        self.classes_ = classes
        self.prototypes_ = self._fit_scaler(X)
        self.prototype_index_ = np.searchsorted(classes, y)
        self._tree = cKDTree(self.prototypes_)
        return self

    def _restore(self) -> None:
        self._tree = cKDTree(self.prototypes_)

    def _predict_index(self, Z):
        _, idx = self._tree.query(Z, k=1, workers=-1)
        return self.prototype_index_[idx]

    def leave_one_out(self, X, y) -> np.ndarray:
        """Exact: each training tile's nearest *other* training tile."""
        _, idx = self._tree.query(self._scaled(np.asarray(X, float)), k=2, workers=-1)
        return self.classes_[self.prototype_index_[idx[:, 1]]]


class LVQClassifier(_Standardised):
    """Kohonen's learning vector quantisation (LVQ1), trained in vectorised batch epochs.

    Prototypes start at k-means centres of each class; each epoch moves every prototype
    towards the mean of the training tiles it wins correctly and away from those it wins
    wrongly, with a learning rate decreasing linearly to zero (the batch form of the
    reference's update rule, so no Python loop runs per tile).

    Parameters
    ----------
    prototypes_per_class : int
        Prototypes per class (fewer when a class has fewer training tiles).
    epochs : int
        Batch epochs of training.
    learning_rate : float
        Initial learning rate, decreasing linearly to zero over the epochs.
    seed : int
        Seed of the k-means start.
    """

    name = "lvq"

    def __init__(self, prototypes_per_class: int = 4, epochs: int = 60,
                 learning_rate: float = 0.3, seed: int = 0):
        self.prototypes_per_class = int(prototypes_per_class)
        self.epochs = int(epochs)
        self.learning_rate = float(learning_rate)
        self.seed = int(seed)

    def fit(self, X, y) -> LVQClassifier:
        from scipy.cluster.vq import kmeans2

        X, y, classes, counts = _check_training(X, y)
        Z = self._fit_scaler(X)
        rng = np.random.default_rng(self.seed)
        protos, owner = [], []
        for i, c in enumerate(classes):
            zc = Z[y == c]
            k = int(min(self.prototypes_per_class, zc.shape[0]))
            with warnings.catch_warnings():
                # an empty cluster just leaves its seed tile as a prototype: harmless here
                warnings.simplefilter("ignore", UserWarning)
                centres, _ = kmeans2(zc, zc[rng.choice(zc.shape[0], k, replace=False)],
                                     minit="matrix", iter=10)
            protos.append(centres)
            owner.append(np.full(k, i))
        P = np.concatenate(protos)
        owner = np.concatenate(owner)
        yi = np.searchsorted(classes, y)
        tree_size = P.shape[0]
        for epoch in range(self.epochs):
            alpha = self.learning_rate * (1 - epoch / self.epochs)
            d = ((Z[:, None, :] - P[None]) ** 2).sum(-1) if Z.shape[0] * tree_size < 5e7 \
                else None
            win = np.argmin(d, axis=1) if d is not None else cKDTree(P).query(Z)[1]
            sign = np.where(owner[win] == yi, 1.0, -1.0)
            pull = np.zeros_like(P)
            np.add.at(pull, win, sign[:, None] * (Z - P[win]))
            hits = np.bincount(win, minlength=tree_size)[:, None]
            P = P + alpha * pull / np.maximum(hits, 1)
        self.classes_ = classes
        self.prototypes_ = P
        self.prototype_owner_ = owner
        self._tree = cKDTree(P)
        return self

    def _restore(self) -> None:
        self._tree = cKDTree(self.prototypes_)

    def _predict_index(self, Z):
        _, idx = self._tree.query(Z, k=1, workers=-1)
        return self.prototype_owner_[idx]

    def leave_one_out(self, X, y, *, folds: int = 10) -> np.ndarray:
        """10-fold cross-validated predictions (exact leave-one-out would retrain n times)."""
        X = np.asarray(X, float)
        y = np.asarray(y)
        rng = np.random.default_rng(self.seed)
        fold = rng.permutation(X.shape[0]) % folds
        pred = np.empty_like(y)
        for f in range(folds):
            test = fold == f
            train = ~test
            if not test.any():
                continue
            if np.unique(y[train]).size < self.classes_.size or \
                    np.bincount(np.searchsorted(self.classes_, y[train])).min() < 2:
                pred[test] = self.predict(X[test])
                continue
            clf = LVQClassifier(self.prototypes_per_class, self.epochs, self.learning_rate,
                                self.seed).fit(X[train], y[train])
            pred[test] = clf.predict(X[test])
        return pred


def make_classifier(name: str):
    """Return an unfitted classifier for ``"gm"``, ``"md"`` or ``"lvq"``."""
    key = str(name).lower()
    if key == "gm":
        return GaussianClassifier(priors="equal")
    if key == "md":
        return MinimumDistanceClassifier()
    if key == "lvq":
        return LVQClassifier()
    raise ValueError(f"unknown classifier {name!r}; choose one of {', '.join(CLASSIFIERS)}.")


def leave_one_out_error(classifier, X, y) -> tuple[float, str]:
    """Leave-one-out error eps_l in percent over the training tiles, and how it was found.

    Exact for GM and MD; LVQ uses 10-fold cross-validation (it would need n retrainings).

    Parameters
    ----------
    classifier : GaussianClassifier, MinimumDistanceClassifier or LVQClassifier
        A classifier of this package (its ``leave_one_out`` method is used).
    X : (n, F) ndarray of float
        Training features, one row per tile.
    y : (n,) ndarray of int
        Training labels.

    Returns
    -------
    error : float
        Percentage of training tiles misclassified when left out.
    method : {"exact", "10-fold"}
        How the error was found.
    """
    pred = classifier.leave_one_out(X, y)
    method = "10-fold" if isinstance(classifier, LVQClassifier) else "exact"
    return float(100.0 * np.mean(pred != np.asarray(y))), method
