import numpy as np
import pytest

from napari_swa_imesh._validation import as_image, as_labels, normalize_spacing


def test_image_checks():
    with pytest.raises(ValueError, match="RGB"):
        as_image(np.zeros((32, 32, 3), np.uint8))
    with pytest.raises(ValueError, match="at least 2-D"):
        as_image(np.zeros(10))
    with pytest.raises(ValueError, match="NaN"):
        as_image(np.array([[1.0, np.nan], [0, 0]]))
    with pytest.raises(TypeError, match="real numbers"):
        as_image(np.array([["a", "b"], ["c", "d"]]))
    with pytest.raises(ValueError, match="empty"):
        as_image(np.zeros((0, 4)))
    src = np.arange(12, dtype=np.uint8).reshape(3, 4)
    out = as_image(src)
    out[0, 0] = 99
    assert src[0, 0] == 0 and out.dtype == np.float64


def test_label_checks():
    with pytest.raises(ValueError, match="non-integer"):
        as_labels(np.array([[0.5, 1.0]]))
    with pytest.raises(ValueError, match="negative"):
        as_labels(np.array([[-1, 1]]))
    assert as_labels(np.array([[1.0, 2.0]])).dtype == np.int32
    assert as_labels(np.array([[True, False]])).tolist() == [[1, 0]]


def test_spacing():
    assert normalize_spacing(None, 2) == (1.0, 1.0)
    assert normalize_spacing([2, 1, 1], 3) == (2.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="one number or 3"):
        normalize_spacing([1, 2], 3)
    with pytest.raises(ValueError, match="positive"):
        normalize_spacing([1, 0, 1], 3)
