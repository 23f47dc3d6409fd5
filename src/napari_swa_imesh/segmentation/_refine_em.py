"""Material means re-estimated inside the classified training image (one EM-style step).

The sample boxes are the largest homogeneous blocks of each material: deep tissue, whose
mean is not the material's (partial volume at boundaries, white matter darker next to grey
matter, deep grey matter brighter). A classifier that trusts the box means puts every
boundary in the wrong place. When the finest level is the pixel value (never on
textures: the value alone does not tell them apart) and the whole training image is in
memory, the fit classifies it (the boxes' Gaussians, coarse-to-fine, Potts MRF), takes
the *interior* of each material's region (eroded by :data:`EROSION` face neighbour, so
boundary partial volume does not pull the mean) among *inliers* (every feature of level
J within :data:`Z_INLIER` box standard deviations of some material: the air around a
head pulls nothing), and moves each material's mean, at every level J..0, to the mean of
those pixels. The covariances stay the boxes'; a material whose interior holds fewer than
:data:`MIN_INTERIOR` pixels keeps its box mean. Prediction is unchanged code (the model
file holds the moved means), so chunked prediction equals in-memory prediction.

Chosen on the tuning generator (``benchmarks/anatomy.py``, dev split; CSF / GM / WM Dice
inside the brain, mean of 4 cases, default -> refined): 3 %, no bias .896 / .942 / .927
-> .890 / .948 / .933; 3 %, 40 % .841 / .921 / .891 -> .844 / .929 / .901; 9 %, none
.829 / .936 / .926 -> .832 / .943 / .937; 9 %, 40 % .791 / .897 / .870 -> .799 / .904 /
.882. Rejected there: re-estimating the covariances too (CSF .896 -> .855 at 3 %),
keeping CSF's box model (CSF -.06), a second round (no better), and an inlier test on the
value alone (at 9 % noise the air passes it and CSF fell to .56). Held-out figures:
``docs/benchmarks/accuracy.md``.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ._mrf import potts_mean_field
from ._window_features import multiscale_features

__all__ = ["refine_fitted", "refine_means", "EROSION", "Z_INLIER", "MIN_INTERIOR"]

EROSION = 1             # face-neighbour erosion of each material's region
Z_INLIER = 3.0          # pixels beyond this many box std devs of every material: ignored
MIN_INTERIOR = 50       # fewer interior pixels: the material keeps its box mean


def refine_fitted(model, source) -> dict:
    """:func:`refine_means` where it applies: the finest level is the pixel value and the
    whole training image is in memory (a :class:`~._training.WholeImage`; a store's fit
    keeps the box means).

    Parameters
    ----------
    model : RecommendedModel
        Fitted on `source`, whose current correction is the one the model was fitted on.
    source : WholeImage or StoreImage

    Returns
    -------
    dict
        :func:`refine_means`'s, or ``{"applied": False, "reason": ...}``.
    """
    if model.finest_scale != 0:
        return {"applied": False, "reason": "the finest level is above the pixel value"}
    work = getattr(source, "work", None)
    if work is None:
        return {"applied": False, "reason": "fitted from a store"}
    return refine_means(model, work)


def refine_means(model, work: np.ndarray) -> dict:
    """Move the class means of the levels a fitted model labels with to its classified
    interiors.

    Parameters
    ----------
    model : RecommendedModel
        Fitted, with ``finest_scale == 0`` (the caller checks). Its classifiers of levels
        ``finest_scale..scale`` get new means (the covariances stay).
    work : (M, N[, P]) ndarray of float32
        The standardised (and bias-corrected) training image the model was fitted on;
        not modified.

    Returns
    -------
    dict
        ``{"applied": True, "box_mean": [...], "mean": [...]}``: the pixel-value means
        before and after, per material in class order (standardised units), for the
        model's scores.
    """
    top = model.levels[model.scale]
    k = top.classes_.size
    feats, _ = multiscale_features(work, model.scale, model.coherence)
    flat = feats.reshape(-1, feats.shape[-1])               # (N, p) features of level J
    del feats
    # inliers: every feature within Z_INLIER box std devs of some material's box mean
    mu = top.means_ * top.scale_ + top.offset_               # (K, p) raw units
    sd = np.sqrt(np.diagonal(top.covariances_, axis1=1, axis2=2)) * top.scale_
    inlier = np.ones(flat.shape[0], bool)
    for f in range(flat.shape[1]):
        inlier &= (flat[:, f] >= np.min(mu[:, f] - Z_INLIER * sd[:, f])) & (
            flat[:, f] <= np.max(mu[:, f] + Z_INLIER * sd[:, f]))
    ll, _ = model._classify_standardised(work.copy())
    lab = potts_mean_field(ll, model.beta, labels_only=True)
    del ll
    st = ndi.generate_binary_structure(work.ndim, 1)
    inner = np.zeros(flat.shape[0], np.int8) - 1            # material of interior inliers
    for c in range(k):
        m = ndi.binary_erosion(lab == c, st, iterations=EROSION).ravel() & inlier
        if np.count_nonzero(m) >= MIN_INTERIOR:
            inner[m] = c
    before = (mu[:, 0]).tolist()
    for j in range(model.finest_scale, model.scale + 1):
        clf = model.levels[j]
        p = clf.means_.shape[1]
        means = clf.means_.copy()
        for c in np.unique(inner[inner >= 0]):
            raw = np.mean(flat[inner == c, :p], axis=0, dtype=np.float64)
            means[c] = (raw - clf.offset_) / clf.scale_
        clf.set_fitted({"means_": means})
    after = (model.levels[model.scale].means_[:, 0] * top.scale_[0] + top.offset_[0])
    return {"applied": True, "box_mean": before, "mean": after.tolist()}
