"""Agreement between a segmentation and a ground truth: Dice, Jaccard, confusion matrix."""

from __future__ import annotations

import numpy as np

from .._validation import IMAGE_NDIM, as_labels

__all__ = ["confusion_matrix", "dice_scores", "jaccard_scores", "evaluate"]


def _pair(labels, truth):
    seg = as_labels(labels, name="labels", min_ndim=IMAGE_NDIM[0], max_ndim=IMAGE_NDIM[-1])
    ref = as_labels(truth, name="truth", min_ndim=IMAGE_NDIM[0], max_ndim=IMAGE_NDIM[-1])
    if seg.shape != ref.shape:
        raise ValueError(
            f"labels of shape {seg.shape} and truth of shape {ref.shape} differ; compare "
            "images of the same shape (use the full-resolution labels)."
        )
    return seg, ref


def confusion_matrix(labels, truth, *, materials=None) -> tuple[np.ndarray, np.ndarray]:
    """Count pixels per (truth, predicted) label pair.

    Parameters
    ----------
    labels, truth : array_like of int, same shape
        Segmentation and ground truth.
    materials : sequence of int, optional
        Labels to tabulate (rows and columns); default every label in either image.

    Returns
    -------
    matrix : (K, K) ndarray of int64
        ``matrix[i, j]`` = pixels whose truth is ``materials[i]`` and prediction ``materials[j]``.
        Pixels whose labels are not in `materials` are not counted.
    materials : (K,) ndarray of int64

    Examples
    --------
    >>> m, k = confusion_matrix([[1, 2], [2, 2]], [[1, 1], [2, 2]])
    >>> m.tolist(), k.tolist()
    ([[1, 1], [0, 2]], [1, 2])
    """
    seg, ref = _pair(labels, truth)
    mats = np.unique(np.concatenate([np.unique(seg), np.unique(ref)])) if materials is None \
        else np.asarray(materials, dtype=np.int64)
    k = mats.size
    si = np.searchsorted(mats, seg.ravel())
    ri = np.searchsorted(mats, ref.ravel())
    ok = (si < k) & (ri < k)
    ok[ok] &= (mats[si[ok]] == seg.ravel()[ok]) & (mats[ri[ok]] == ref.ravel()[ok])
    matrix = np.bincount(ri[ok] * k + si[ok], minlength=k * k).reshape(k, k)
    return matrix.astype(np.int64), mats.astype(np.int64)


def dice_scores(labels, truth, *, materials=None) -> dict[int, float]:
    """Dice coefficient per material, eq. 2.36: ``2 |S ∩ G| / (|S| + |G|)``.

    Materials default to the labels above 0 present in the truth. A material absent
    from both images scores NaN.

    Parameters
    ----------
    labels : ndarray of int
        The segmentation.
    truth : ndarray of int
        The reference labels, same shape.
    materials : sequence of int, optional
        Materials to score (default: the labels above 0 in `truth`).

    Returns
    -------
    dict of int to float
        Dice per material, in [0, 1].
    """
    seg, ref = _pair(labels, truth)
    return {k: v[0] for k, v in _overlaps(seg, ref, materials).items()}


def jaccard_scores(labels, truth, *, materials=None) -> dict[int, float]:
    """Tanimoto/Jaccard coefficient per material, eq. 2.37: ``|S ∩ G| / |S ∪ G|``.

    Parameters
    ----------
    labels : ndarray of int
        The segmentation.
    truth : ndarray of int
        The reference labels, same shape.
    materials : sequence of int, optional
        Materials to score (default: the labels above 0 in `truth`).

    Returns
    -------
    dict of int to float
        Jaccard per material, in [0, 1] (NaN for a material absent from both).
    """
    seg, ref = _pair(labels, truth)
    return {k: v[1] for k, v in _overlaps(seg, ref, materials).items()}


def _overlaps(seg, ref, materials):
    mats = [int(m) for m in np.unique(ref) if m > 0] if materials is None else \
        [int(m) for m in materials]
    out = {}
    for m in mats:
        s = seg == m
        g = ref == m
        inter = np.count_nonzero(s & g)
        ns, ng = np.count_nonzero(s), np.count_nonzero(g)
        union = ns + ng - inter
        out[m] = (2 * inter / (ns + ng) if ns + ng else float("nan"),
                  inter / union if union else float("nan"))
    return out


def evaluate(labels, truth, *, materials=None) -> dict:
    """Dice, Jaccard and confusion matrix in one dictionary (what ``swa-imesh evaluate`` prints).

    Parameters
    ----------
    labels : ndarray of int
        The segmentation.
    truth : ndarray of int
        The reference labels, same shape.
    materials : sequence of int, optional
        Materials to score (default: the labels above 0 in `truth`).

    Returns
    -------
    dict
        ``materials`` (list), ``dice`` and ``jaccard`` (material to score),
        ``mean_dice``, ``accuracy`` (fraction of pixels equal), ``confusion_labels`` and
        ``confusion`` (rows: truth, columns: segmentation, as lists).
    """
    seg, ref = _pair(labels, truth)
    ov = _overlaps(seg, ref, materials)
    matrix, mats = confusion_matrix(seg, ref)
    dice = {m: v[0] for m, v in ov.items()}
    return {
        "materials": list(ov),
        "dice": dice,
        "jaccard": {m: v[1] for m, v in ov.items()},
        "mean_dice": float(np.nanmean(list(dice.values()))) if dice else float("nan"),
        "accuracy": float(np.mean(seg == ref)),
        "confusion_labels": mats.tolist(),
        "confusion": matrix.tolist(),
    }
