import numpy as np
import pytest
from scipy import stats

from napari_swa_imesh.segmentation._res import plot_res, res_statistics
from napari_swa_imesh.segmentation._samples import Samples


def blocky_texture(shape, block, seed):
    """Constant blocks of `block` px with iid values: statistics settle past the block size."""
    rng = np.random.default_rng(seed)
    coarse = rng.normal(0, 1, tuple(-(-n // block) for n in shape))
    out = coarse
    for a in range(len(shape)):
        out = np.repeat(out, block, axis=a)
    return out[tuple(slice(0, n) for n in shape)]


def two_material_image():
    img = np.concatenate([blocky_texture((256, 128), 8, 0),
                          5 + 2 * blocky_texture((256, 128), 8, 1)], axis=1)
    s = Samples.from_dict({"materials": [{"label": 1, "name": "a"}, {"label": 2, "name": "b"}],
                           "boxes": [{"label": 1, "start": [0, 0], "stop": [256, 128]},
                                     {"label": 2, "start": [0, 128], "stop": [256, 256]}]})
    return img, s


def test_statistics_match_brute_force_tiles():
    rng = np.random.default_rng(3)
    img = rng.gamma(2.0, 1.0, (50, 45))
    s = Samples.from_dict({"boxes": [{"label": 1, "start": [2, 3], "stop": [34, 40]},
                                     {"label": 2, "start": [30, 0], "stop": [50, 20]}]})
    st = res_statistics(img, s, max_scale=3)
    for i, label in enumerate((1, 2)):
        box = s.boxes_of(label)[0]
        crop = img[box.slices]
        for j in st.scales:
            t = 1 << j
            n0, n1 = crop.shape[0] // t, crop.shape[1] // t
            tiles = crop[:n0 * t, :n1 * t].reshape(n0, t, n1, t).swapaxes(1, 2).reshape(-1, t * t)
            assert st.n_tiles[i, j] == tiles.shape[0]
            if tiles.shape[0] < 4:
                assert np.isnan(st.mean[i, j]).all()
                continue
            if j == 0:
                continue  # one-pixel tiles: variance 0 by definition, shape by convention
            ref = np.c_[tiles.mean(1), tiles.var(1), stats.skew(tiles, axis=1),
                        stats.kurtosis(tiles, axis=1, fisher=True) + 3]
            np.testing.assert_allclose(st.mean[i, j], ref.mean(0), rtol=1e-9)
            np.testing.assert_allclose(st.std[i, j], ref.std(0), rtol=1e-7, atol=1e-12)
            np.testing.assert_allclose(st.min[i, j], ref.min(0), rtol=1e-9)
            np.testing.assert_allclose(st.max[i, j], ref.max(0), rtol=1e-9)


def test_suggested_res_is_where_blocky_texture_settles():
    # 8-px blocks: tiles up to 8 px are constant; variance reaches 3/4, 15/16, 63/64 of the
    # block variance at 16, 32, 64 px, so the 10% drift rule settles at 64 px (scale 6)
    img, s = two_material_image()
    st = res_statistics(img, s)
    assert st.material_res == {1: 6, 2: 6}
    assert st.suggested_scale == 6
    assert "6" in st.reason


def test_res_caps_at_trainable_scale_and_reports():
    img, s = two_material_image()
    s2 = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [64, 64]},
                                      {"label": 2, "start": [0, 128], "stop": [256, 256]}]})
    st = res_statistics(img, s2)
    assert st.suggested_scale is not None
    assert (st.n_tiles[:, st.suggested_scale] >= 2).all()


def test_plot_layout():
    img, s = two_material_image()
    st = res_statistics(img, s, max_scale=6)
    fig = plot_res(st, selected_scale=4)
    axes = fig.get_axes()
    assert len(axes) == 4 * 2
    assert axes[0].get_title() == "a" and axes[0].get_ylabel() == "mean"
    # line: mean, two dotted lines: min and max, vertical lines for suggested and chosen
    assert len(axes[0].get_lines()) >= 4


def test_box_outside_image_is_an_error():
    img, s = two_material_image()
    bad = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [300, 10]}]})
    with pytest.raises(ValueError, match="outside the image"):
        res_statistics(img, bad)
