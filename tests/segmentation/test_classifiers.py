import numpy as np
import pytest

from napari_swa_imesh.segmentation._classifiers import (
    GaussianClassifier,
    LVQClassifier,
    MinimumDistanceClassifier,
    leave_one_out_error,
    make_classifier,
)


def two_blobs(seed=0, n=(40, 60), p=3):
    rng = np.random.default_rng(seed)
    X = np.concatenate([rng.normal(0, 1, (n[0], p)), rng.normal(1.5, 2.0, (n[1], p))])
    y = np.r_[np.full(n[0], 3), np.full(n[1], 7)]
    return X, y


def gm_by_hand(X, y, x):
    """Eq. 2.30 straight from its definition, with numpy's own covariance."""
    best, arg = np.inf, None
    for c in np.unique(y):
        Xc = X[y == c]
        mu = Xc.mean(0)
        C = np.cov(Xc.T, bias=True)
        g = -np.log(len(Xc) / len(X)) + 0.5 * np.linalg.slogdet(C)[1] \
            + 0.5 * (x - mu) @ np.linalg.solve(C, x - mu)
        if g < best:
            best, arg = g, c
    return arg


def test_gm_matches_quadratic_discriminant_by_hand():
    X, y = two_blobs()
    clf = GaussianClassifier(shrinkage=0.0).fit(X, y)
    rng = np.random.default_rng(1)
    Q = rng.normal(0.7, 2.0, (200, 3))
    expected = np.array([gm_by_hand(X, y, q) for q in Q])
    np.testing.assert_array_equal(clf.predict(Q), expected)


def test_gm_priors_and_labels_kept():
    X, y = two_blobs()
    clf = GaussianClassifier().fit(X, y)
    np.testing.assert_allclose(clf.priors_, [0.4, 0.6])
    assert set(np.unique(clf.predict(X))) <= {3, 7}


@pytest.mark.parametrize("name", ["gm", "md"])
def test_exact_leave_one_out_matches_refitting(name):
    X, y = two_blobs(seed=2, n=(15, 20))
    clf = make_classifier(name).fit(X, y)
    fast = clf.leave_one_out(X, y)
    slow = np.array([
        make_classifier(name).fit(np.delete(X, i, 0), np.delete(y, i)).predict(X[i:i + 1])[0]
        for i in range(len(y))])
    np.testing.assert_array_equal(fast, slow)
    err, how = leave_one_out_error(clf, X, y)
    assert how == "exact"
    assert err == pytest.approx(100 * np.mean(slow != y))


def test_md_is_nearest_training_tile():
    X, y = two_blobs(seed=3)
    clf = MinimumDistanceClassifier().fit(X, y)
    Q = np.random.default_rng(4).normal(0.5, 2, (50, 3))
    Z = (X - X.mean(0)) / X.std(0)
    Zq = (Q - X.mean(0)) / X.std(0)
    nearest = np.argmin(((Zq[:, None] - Z[None]) ** 2).sum(-1), axis=1)
    np.testing.assert_array_equal(clf.predict(Q), y[nearest])


def test_lvq_separates_separable_classes_and_reports_cv():
    rng = np.random.default_rng(5)
    X = np.concatenate([rng.normal(0, 0.3, (50, 2)), rng.normal(3, 0.3, (50, 2))])
    y = np.r_[np.ones(50, int), np.full(50, 2)]
    clf = LVQClassifier(seed=0).fit(X, y)
    assert (clf.predict(X) == y).all()
    err, how = leave_one_out_error(clf, X, y)
    assert how == "10-fold" and err == 0.0


def test_singular_covariance_is_regularised_not_fatal():
    # a constant class (all tiles identical) and a class living on a line
    X = np.concatenate([np.zeros((10, 3)), np.c_[np.arange(10.0), np.arange(10.0), np.ones(10)]])
    y = np.r_[np.ones(10, int), np.full(10, 2)]
    clf = GaussianClassifier().fit(X, y)
    assert np.isfinite(clf.logdet_).all()
    assert clf.regularized_.all()
    assert (clf.predict(X) == y).mean() >= 0.9


def test_errors_are_clear():
    X, y = two_blobs()
    with pytest.raises(ValueError, match="fewer than 2 training tiles"):
        GaussianClassifier().fit(X[:41], y[:41])
    with pytest.raises(ValueError, match="at least two materials"):
        GaussianClassifier().fit(X[:40], y[:40])
    with pytest.raises(ValueError, match="NaN"):
        GaussianClassifier().fit(np.where(X > 3, np.nan, X), y)
    with pytest.raises(ValueError, match="unknown classifier"):
        make_classifier("svm")


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_log_likelihood_is_eq_2_30_by_hand(dtype):
    X, y = two_blobs(seed=3)
    clf = GaussianClassifier(shrinkage=0.0, priors="proportional").fit(X, y)
    Q = np.random.default_rng(4).normal(0.5, 2.0, (50, 3))
    want = []
    for c in clf.classes_:
        Xc = X[y == c]
        C = np.cov(Xc.T, bias=True)
        r = Q - Xc.mean(0)
        want.append(np.log(len(Xc) / len(X)) - 0.5 * np.linalg.slogdet(C)[1]
                    - 0.5 * np.einsum("ij,ij->i", r, np.linalg.solve(C, r.T).T))
    # the constant -p/2 log(2 pi) is common to all classes and left out; standardisation
    # shifts every class by the same log|det scale|
    got = clf.log_likelihood(Q, dtype=dtype)
    assert got.shape == (2, 50) and got.dtype == dtype
    shift = np.log(clf.scale_).sum()
    np.testing.assert_allclose(got - shift, np.array(want),
                               rtol=1e-5 if dtype == np.float32 else 1e-9, atol=1e-4)
    np.testing.assert_array_equal(clf.predict(Q), clf.classes_[np.argmax(got, axis=0)])


@pytest.mark.parametrize("name", ["gm", "md", "lvq"])
def test_get_params_are_constructor_parameters_only(name):
    X, y = two_blobs()
    clf = make_classifier(name).fit(X, y)
    params = clf.get_params()
    assert not any(k.endswith("_") for k in params)
    again = type(clf)(**params)                          # scikit-learn's round trip
    assert again.get_params() == params
    restored = type(clf)(**params).set_fitted(clf.fitted_arrays())
    np.testing.assert_array_equal(restored.predict(X), clf.predict(X))
    with pytest.raises(ValueError, match="has no parameter"):
        clf.set_params(bogus=1)
