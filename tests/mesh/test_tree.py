"""Region tree properties the mesher relies on (the tree is the mesher's own, in
mesh/mesher/_tree.py)."""

import numpy as np
import pytest

from napari_swa_imesh import build_tree
from napari_swa_imesh._region_tree import PAD_LABEL


@pytest.mark.parametrize("shape", [(16, 16), (13, 7), (5, 9, 6), (4, 6, 3, 5)])
def test_leaves_tile_the_image_and_are_maximal(shape):
    rng = np.random.default_rng(sum(shape))
    lab = (rng.random(shape) < 0.1).astype(np.int64) + (rng.random(shape) < 0.05)
    tree = build_tree(lab)
    np.testing.assert_array_equal(tree.to_image(), lab)
    # every pixel of the padded grid is covered exactly once
    count = tree.to_image(values=np.ones(len(tree), np.int64), fill=0, crop=False)
    cover = np.zeros(tree.padded_shape, np.int64)
    for lev in np.unique(tree.level):
        sel = tree.level == lev
        cover += tree.select(sel).to_image(values=np.ones(sel.sum(), np.int64), fill=0, crop=False)
    assert (cover == 1).all() and (count == 1).all()
    # maximal: the parent block of every leaf below the top is not homogeneous
    padded = tree.to_image(crop=False)
    for o, lev in zip(tree.origin, tree.level):
        if lev == tree.top_level:
            continue
        s = 2 << int(lev)
        block = padded[tuple(slice(c // s * s, c // s * s + s) for c in o)]
        assert block.min() != block.max()


def test_padding_is_separate():
    tree = build_tree(np.ones((5, 6), np.int64))
    assert tree.padded_shape == (8, 8)
    assert set(tree.label[~tree.inside].tolist()) == {PAD_LABEL}
    assert (tree.to_image(values=tree.label) == 1).all()


@pytest.mark.parametrize("shape", [(13, 7), (5, 6, 9), (16, 16, 16), (3, 40), (4, 3, 5, 2)])
def test_leaf_finder_agrees_with_the_painted_leaf_image(shape):
    from napari_swa_imesh._region_tree import leaf_finder

    rng = np.random.default_rng(len(shape))
    lab = (rng.random(shape) < 0.1).astype(np.uint8)
    tree = build_tree(lab)
    painted = tree.to_image(values=np.arange(len(tree)), crop=False)
    pixels = np.stack(np.unravel_index(np.arange(painted.size), painted.shape), axis=1)
    np.testing.assert_array_equal(leaf_finder(tree)(pixels), painted.ravel())
