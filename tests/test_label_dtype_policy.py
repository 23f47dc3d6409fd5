"""The one label-dtype policy (issue 24): ``_validation.label_dtype`` decides, and
``io.label_array`` (files, display) and ``as_labels`` (the door of compute) follow it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from napari_swa_imesh._validation import as_labels, label_dtype
from napari_swa_imesh.io import label_array

INTEGER_DTYPES = [np.bool_, np.int8, np.int16, np.int32, np.int64,
                  np.uint8, np.uint16, np.uint32, np.uint64]
INT64_MAX = int(np.iinfo(np.int64).max)


def _smallest(lo: int, hi: int) -> np.dtype:
    """The reference: numpy's own smallest types, worked out another way."""
    if lo >= 0:
        return np.min_scalar_type(hi)
    return np.promote_types(np.min_scalar_type(lo), np.min_scalar_type(-max(hi, 0) - 1))


def _compute(hi: int) -> np.dtype:
    return np.dtype(np.int32 if hi <= np.iinfo(np.int32).max else np.int64)


@pytest.mark.parametrize("dtype", INTEGER_DTYPES, ids=lambda d: np.dtype(d).name)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_every_integer_or_bool_dtype_maps_per_the_policy(dtype, data):
    arr = data.draw(hnp.arrays(dtype, hnp.array_shapes(min_dims=1, max_dims=3, max_side=5)))
    lo, hi = int(arr.min()), int(arr.max())
    kept = arr.copy()

    written = label_array(arr)
    assert written.dtype == _smallest(lo, hi) == label_dtype(arr, smallest=True)
    assert written.tolist() == arr.astype(object).tolist()        # every value exact
    assert label_dtype(arr) == _compute(hi)

    if lo >= 0 and hi <= INT64_MAX:
        door = as_labels(arr)
        assert np.shares_memory(door, arr)                         # never a copy
        assert door.dtype == (np.uint8 if arr.dtype == np.bool_ else arr.dtype)
    else:
        with pytest.raises(ValueError, match="negative values|above"):
            as_labels(arr)
    np.testing.assert_array_equal(arr, kept)                       # input not mutated


@settings(max_examples=60, deadline=None)
@given(values=st.lists(st.integers(0, 2**40), min_size=1, max_size=12),
       ftype=st.sampled_from([np.float32, np.float64]))
def test_whole_valued_floats_map_per_the_policy(values, ftype):
    arr = np.asarray(values, dtype=ftype)
    exact = [int(v) for v in arr]                # what the float holds (float32 rounds)
    hi = max(exact)
    door = as_labels(arr)
    assert door.dtype == _compute(hi) and door.tolist() == exact
    written = label_array(arr)
    assert written.dtype == _smallest(min(exact), hi) and written.tolist() == exact


@settings(max_examples=60, deadline=None)
@given(values=st.lists(st.integers(0, 1000), min_size=1, max_size=8),
       fraction=st.floats(0.01, 0.99), where=st.integers(0, 7),
       ftype=st.sampled_from([np.float32, np.float64]))
def test_floats_with_a_non_integer_are_refused(values, fraction, where, ftype):
    arr = np.asarray(values, dtype=ftype)
    arr[where % arr.size] += ftype(fraction)
    with pytest.raises(ValueError, match="non-integer"):
        as_labels(arr)
    with pytest.raises(ValueError, match="non-integer"):
        label_array(arr)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_and_infinity_are_refused(bad):
    for check in (as_labels, label_array):
        with pytest.raises(ValueError, match="non-integer"):
            check(np.array([1.0, bad]))


def test_the_policy_on_material_lists_and_the_edges():
    assert label_dtype([]) == np.int32 and label_dtype([2**31 - 1]) == np.int32
    assert label_dtype([2**31]) == np.int64
    assert label_dtype([255], smallest=True) == np.uint8
    assert label_dtype([256], smallest=True) == np.uint16
    assert label_dtype([-128, 127], smallest=True) == np.int8
    assert label_dtype([-129], smallest=True) == np.int16
    assert label_array(np.zeros((0, 3))).dtype == np.uint8
