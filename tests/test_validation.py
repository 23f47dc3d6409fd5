import re

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


# --------------------------------------------------- "no silent wrong result" cases


def test_uint64_labels_above_int64_are_not_called_negative():
    big = np.array([[0, 2**63 + 5], [1, 1]], dtype=np.uint64)
    with pytest.raises(ValueError, match=r"values up to 9223372036854775813, above "
                                         r"9223372036854775807") as info:
        as_labels(big)
    assert "negative" not in str(info.value)
    # uint64 labels that int64 holds are kept exactly, in their own dtype
    fits = np.array([[0, 2**63 - 1], [1, 1]], dtype=np.uint64)
    assert as_labels(fits) is fits


@pytest.mark.parametrize("dtype", [np.uint8, np.int8, np.uint16, np.int32, np.uint64])
def test_integer_labels_are_not_copied(dtype):
    lab = np.array([[0, 1], [2, 3]], dtype=dtype)
    out = as_labels(lab)
    assert out is lab and out.dtype == dtype


def test_boolean_labels_are_a_uint8_view():
    mask = np.array([[True, False], [False, True]])
    out = as_labels(mask)
    assert out.dtype == np.uint8 and np.shares_memory(out, mask)


@pytest.mark.parametrize("value", [1e-300, 1e300, 1e-31, 1e31])
def test_spacing_that_overflows_or_underflows_is_refused(value):
    with pytest.raises(ValueError, match="between 1e-30 and 1e[+]30.*other units"):
        normalize_spacing(value, 3)
    with pytest.raises(ValueError, match="other units"):
        normalize_spacing([1.0, value], 2)
    assert normalize_spacing([1e-30, 1e30], 2) == (1e-30, 1e30)


@pytest.mark.parametrize(
    ("call", "bad"),
    [
        (lambda: normalize_spacing((np.float64(0.0), np.float64(1.0)), 2), "0, 1"),
        (lambda: normalize_spacing((np.float64(1.0),) * 2, 3), "1.0, 1.0"),
        (lambda: normalize_spacing((np.float64(-2.5),), 2), "-2.5"),
        (lambda: as_labels(np.array([[-3, 1]], np.int64)), "min -3"),
        (lambda: as_labels(np.zeros((2, 2, 2, 2)), min_ndim=2, max_ndim=3), "2-D to 3-D"),
    ],
)
def test_error_texts_print_plain_numbers_not_python_reprs(call, bad):
    with pytest.raises(ValueError, match=re.escape(bad)) as info:
        call()
    text = str(info.value)
    assert bad in text
    for leak in ("np.float64(", "np.int64(", "np.uint", "max_ndim", "min_ndim", "array("):
        assert leak not in text, text


def test_json_output_turns_every_non_finite_number_into_null():
    import json

    import numpy as np

    from napari_swa_imesh._cli_util import to_jsonable

    data = {"a": np.float64("nan"), "b": [np.float32("inf"), float("-inf")],
            "c": np.array([1.0, np.nan]), "d": np.int64(3)}
    text = json.dumps(to_jsonable(data), allow_nan=False)
    assert json.loads(text) == {"a": None, "b": [None, None], "c": [1.0, None], "d": 3}
