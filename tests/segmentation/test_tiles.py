"""The library calls that replaced hand-written reductions give the old results."""

import numpy as np
import pytest
from scipy import ndimage as ndi

from napari_swa_imesh.segmentation._bias import upsample_linear, upsample_linear_at
from napari_swa_imesh.segmentation._tiles import (
    block_mean,
    block_sum,
    majority_tiles,
    tile_counts,
)


# -- the implementations they replaced, kept here as references ---------------------------
def old_box(x, size):
    out = x
    for axis in range(x.ndim):
        out = ndi.uniform_filter1d(out, size, axis=axis, mode="reflect")
    return out


def old_block_mean(a, factor):
    out = a
    for axis in range(a.ndim):
        n = out.shape[axis]
        starts = np.arange(0, n, factor)
        out = np.add.reduceat(out, starts, axis=axis) / np.diff(
            np.append(starts, n)).reshape((-1,) + (1,) * (a.ndim - axis - 1))
    return out


def old_upsample_linear(small, shape):
    out = small
    for axis, n in enumerate(shape):
        m = small.shape[axis]
        pos = np.clip((np.arange(n) + 0.5) * m / n - 0.5, 0, m - 1)
        lo = np.floor(pos).astype(np.intp)
        hi = np.minimum(lo + 1, m - 1)
        w = (pos - lo).astype(np.float32).reshape((-1,) + (1,) * (len(shape) - axis - 1))
        out = np.take(out, lo, axis=axis) * (1 - w) + np.take(out, hi, axis=axis) * w
    return out


def old_block_sum(mask, s):
    tiles = tuple(-(-n // s) for n in mask.shape)
    padded = np.zeros(tuple(t * s for t in tiles), np.uint8)
    padded[tuple(slice(0, n) for n in mask.shape)] = mask
    blocks = padded.reshape(tuple(v for t in tiles for v in (t, s)))
    return blocks.sum(axis=tuple(range(1, 2 * mask.ndim, 2)), dtype=np.int32)


SHAPES = [(17, 23), (9, 12, 7), (4, 5, 3, 6)]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("size", [3, 5, 9])
def test_uniform_filter_is_the_old_box_exactly(shape, size):
    x = np.random.default_rng(size).normal(3, 2, shape).astype(np.float32)
    np.testing.assert_array_equal(ndi.uniform_filter(x, size, mode="reflect"),
                                  old_box(x, size))


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("factor", [1, 2, 3, 5])
def test_block_mean_is_the_old_one_including_partial_blocks(shape, factor):
    a = np.random.default_rng(factor).random(shape).astype(np.float32) * 10
    new = block_mean(a, factor)
    old = old_block_mean(a, factor)
    assert new.shape == old.shape
    np.testing.assert_allclose(new, old, rtol=1e-6)   # summation order only


@pytest.mark.parametrize("small,shape", [((8, 8), (256, 256)), ((5, 7, 6), (37, 50, 41)),
                                         ((3, 4), (3, 4)), ((1, 5), (7, 9))])
def test_zoom_is_the_old_linear_upsampling(small, shape):
    a = (np.random.default_rng(0).random(small) + 0.5).astype(np.float32)
    new = upsample_linear(a, shape)
    assert new.shape == shape and new.dtype == np.float32
    np.testing.assert_allclose(new, old_upsample_linear(a, shape), rtol=1e-6)  # 2 ulp


@pytest.mark.parametrize("small,shape", [((8, 8), (256, 256)), ((5, 7, 6), (37, 50, 41)),
                                         ((16, 9, 12), (64, 40, 47)), ((1, 5), (7, 9))])
def test_upsampling_is_scipys_linear_zoom_and_blocks_are_its_slices(small, shape):
    """The separable code is ndimage.zoom's grid-mode linear zoom (which it replaced for
    speed), and a block or strided region equals that slice exactly (chunked runs)."""
    a = (np.random.default_rng(1).random(small) + 0.5).astype(np.float32)
    whole = upsample_linear(a, shape)
    zoom = ndi.zoom(a, [n / m for n, m in zip(shape, small)], order=1, mode="nearest",
                    grid_mode=True, prefilter=False)
    np.testing.assert_allclose(whole, zoom, rtol=3e-7)
    region = [np.arange(n // 3, n - 1) for n in shape[:-1]] + [np.arange(0, shape[-1], 3)]
    np.testing.assert_array_equal(upsample_linear_at(a, shape, region), whole[np.ix_(*region)])


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("s", [2, 4])
def test_block_sum_counts_exactly(shape, s):
    mask = np.random.default_rng(s).random(shape) > 0.4
    got = block_sum(mask, s, dtype=np.int32)
    np.testing.assert_array_equal(got, old_block_sum(mask, s))
    scale = s.bit_length() - 1
    np.testing.assert_array_equal(tile_counts(shape, scale, mask), got)
    np.testing.assert_array_equal(tile_counts(shape, scale, None),
                                  block_sum(np.ones(shape, bool), s, dtype=np.int64))


def test_majority_tiles_ties_go_to_the_smallest_label_in_any_order():
    labels = np.array([[3, 7], [7, 3]])
    for order in ([3, 7], [7, 3]):
        assert majority_tiles(labels, 1, order).tolist() == [[3]]
