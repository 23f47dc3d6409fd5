import numpy as np
import pytest

from napari_swa_imesh.segmentation._metrics import (
    confusion_matrix,
    dice_scores,
    evaluate,
    jaccard_scores,
)


def test_scores_by_hand():
    truth = np.array([[1, 1, 2, 2], [1, 1, 2, 2]])
    seg = np.array([[1, 2, 2, 2], [1, 1, 2, 2]])
    # material 1: |S|=3, |G|=4, |S∩G|=3
    assert dice_scores(seg, truth)[1] == pytest.approx(6 / 7)
    assert jaccard_scores(seg, truth)[1] == pytest.approx(3 / 4)
    assert dice_scores(seg, truth)[2] == pytest.approx(8 / 9)
    m, k = confusion_matrix(seg, truth)
    assert k.tolist() == [1, 2] and m.tolist() == [[3, 1], [0, 4]]


def test_random_against_definitions():
    rng = np.random.default_rng(0)
    truth = rng.integers(0, 4, (30, 20))
    seg = rng.integers(0, 4, (30, 20))
    d, j = dice_scores(seg, truth), jaccard_scores(seg, truth)
    for m in (1, 2, 3):
        s, g = seg == m, truth == m
        assert d[m] == pytest.approx(2 * (s & g).sum() / (s.sum() + g.sum()))
        assert j[m] == pytest.approx((s & g).sum() / (s | g).sum())
        assert j[m] <= d[m]
    m, k = confusion_matrix(seg, truth)
    assert m.sum() == seg.size and k.tolist() == [0, 1, 2, 3]
    ev = evaluate(seg, truth)
    assert ev["mean_dice"] == pytest.approx(np.mean(list(d.values())))


def test_shape_mismatch_is_clear():
    with pytest.raises(ValueError, match="differ"):
        dice_scores(np.zeros((4, 4), int), np.zeros((4, 5), int))
