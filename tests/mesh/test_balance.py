"""2:1 balance: brute force against a per-pixel level map and a naive splitting loop."""

import numpy as np
import pytest
from imesh_cases import blobs, noise

from napari_swa_imesh import build_tree
from napari_swa_imesh._region_tree import RegionTree
from napari_swa_imesh.mesh.mesher._balance import balance_tree, balance_violations


def _naive_balance(tree: RegionTree, connectivity: int) -> np.ndarray:
    """Per-pixel level map of the minimal balanced refinement, by splitting until stable."""
    level = tree.to_image(values=tree.level.astype(np.int64), crop=False)
    d = level.ndim
    offsets = [np.array(o) - 1 for o in np.ndindex((3,) * d)
               if 0 < np.count_nonzero(np.array(o) - 1) <= connectivity]
    changed = True
    while changed:
        changed = False
        # leaves of the current level map: blocks of side 2**lev aligned on 2**lev
        for idx in zip(*np.nonzero(level >= 0)):
            lev = int(level[idx])
            s = 1 << lev
            if lev == 0 or any(c % s for c in idx):
                continue
            if level[tuple(slice(c, c + s) for c in idx)].max() != lev:
                continue  # not the origin of a leaf of this level
            lo = np.array(idx)
            for off in offsets:
                # pixels of the neighbour region touching this leaf
                a = np.where(off < 0, lo - 1, np.where(off > 0, lo + s, lo))
                b = np.where(off < 0, lo, np.where(off > 0, lo + s + 1, lo + s))
                if (a < 0).any() or (b > np.array(level.shape)).any():
                    continue
                if level[tuple(slice(x, y) for x, y in zip(a, b))].min() < lev - 1:
                    level[tuple(slice(c, c + s) for c in idx)] = lev - 1
                    changed = True
                    break
    return level


@pytest.mark.parametrize("connectivity", [1, 2, 3])
@pytest.mark.parametrize("shape,seed",
                         [((16, 16), 0), ((13, 20), 1), ((8, 8, 8), 2), ((9, 7, 12), 3)])
def test_balanced_and_minimal(shape, seed, connectivity):
    d = len(shape)
    if connectivity > d:
        pytest.skip("connectivity above the dimension")
    lab = noise(shape, 3, seed, p=0.03)
    tree = build_tree(lab)
    bal = balance_tree(tree, connectivity=connectivity)
    assert balance_violations(bal, connectivity=connectivity) == 0
    # a refinement: same labels, every leaf inside a leaf of the region tree
    np.testing.assert_array_equal(bal.to_image(), lab)
    before = tree.to_image(values=tree.level.astype(np.int64), crop=False)
    after = bal.to_image(values=bal.level.astype(np.int64), crop=False)
    assert (after <= before).all()
    # minimal: equal to splitting leaf by leaf until nothing changes
    np.testing.assert_array_equal(after, _naive_balance(tree, connectivity))
    # idempotent
    again = balance_tree(bal, connectivity=connectivity)
    assert len(again) == len(bal)


def test_violations_detect_an_unbalanced_tree():
    lab = np.zeros((16, 16), np.int64)
    lab[7, 7] = 1
    tree = build_tree(lab)
    assert balance_violations(tree) > 0
    assert balance_violations(balance_tree(tree)) == 0


@pytest.mark.parametrize("d", [2, 3, 4])
def test_n_dimensional_and_stronger_balance_costs_leaves(d):
    lab = blobs((8,) * d, 3, seed=d, sigma=1.0)
    tree = build_tree(lab)
    counts = [len(balance_tree(tree, connectivity=c)) for c in range(1, d + 1)]
    assert counts == sorted(counts)
    for c in range(1, d + 1):
        assert balance_violations(balance_tree(tree, connectivity=c), connectivity=c) == 0


def test_bad_connectivity():
    with pytest.raises(ValueError, match="connectivity must be 1..2"):
        balance_tree(build_tree(np.ones((4, 4), int)), connectivity=3)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_dilate_is_scipy_binary_dilation(d):
    """The numpy dilation the balance uses (no scipy.ndimage import) against scipy's."""
    from scipy import ndimage

    from napari_swa_imesh.mesh.mesher._balance import _dilate

    rng = np.random.default_rng(d)
    for _ in range(20):
        grid = rng.random(tuple(rng.integers(1, 9, d))) < 0.15
        for c in range(1, d + 1):
            expected = ndimage.binary_dilation(grid, ndimage.generate_binary_structure(d, c))
            np.testing.assert_array_equal(_dilate(grid, c), expected)
