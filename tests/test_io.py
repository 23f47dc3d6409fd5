import numpy as np
import pytest

from napari_swa_imesh.io import read_image, write_labels


@pytest.mark.parametrize("suffix,shape", [(".npy", (5, 6, 7)), (".tif", (5, 6, 7)),
                                          (".nii.gz", (5, 6, 7)), (".png", (6, 7)),
                                          (".tif", (9, 4))])
def test_labels_round_trip_with_spacing(tmp_path, suffix, shape):
    rng = np.random.default_rng(0)
    labels = rng.integers(0, 5, shape)
    spacing = (2.0, 0.5, 0.5)[-len(shape):] if suffix in (".tif", ".nii.gz") else None
    p = write_labels(tmp_path / f"lab{suffix}", labels, spacing=spacing)
    back, sp = read_image(p)
    np.testing.assert_array_equal(back, labels)
    if spacing:
        np.testing.assert_allclose(sp, spacing, rtol=1e-6)


def test_never_overwrites_without_force(tmp_path):
    p = tmp_path / "lab.npy"
    np.save(p, np.arange(3))
    with pytest.raises(FileExistsError, match="--force"):
        write_labels(p, np.zeros((4, 4), int))
    np.testing.assert_array_equal(np.load(p), np.arange(3))
    write_labels(p, np.zeros((4, 4), int), force=True)
    assert np.load(p).shape == (4, 4)


def test_unreadable_and_unknown_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="no image file"):
        read_image(tmp_path / "missing.tif")
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"not a tiff at all")
    with pytest.raises(ValueError, match="cannot read"):
        read_image(bad)
    odd = tmp_path / "x.xyz"
    odd.write_text("1")
    with pytest.raises(ValueError, match="unknown suffix"):
        read_image(odd)
    with pytest.raises(ValueError, match="cannot write labels"):
        write_labels(tmp_path / "a.bmp", np.zeros((3, 3), int))


def test_gray_converts_rgb(tmp_path):
    import imageio.v3 as iio

    rgb = np.zeros((8, 9, 3), np.uint8)
    rgb[..., 1] = 200
    iio.imwrite(tmp_path / "c.png", rgb)
    img, _ = read_image(tmp_path / "c.png")
    assert img.shape == (8, 9, 3)
    gray, sp = read_image(tmp_path / "c.png", gray=True)
    assert gray.shape == (8, 9) and sp == (1.0, 1.0)


def test_atomic_write_moves_a_store_folder_into_place_and_replaces_it_whole(tmp_path):
    from napari_swa_imesh.io import atomic_write

    target = tmp_path / "labels.zarr"
    with atomic_write([target]) as (tmp,):
        assert tmp.parent.parent == tmp_path and not target.exists()
        (tmp / "c").mkdir(parents=True)
        (tmp / "c" / "0").write_text("first")
    assert (target / "c" / "0").read_text() == "first"
    with pytest.raises(FileExistsError, match="already exists"):
        with atomic_write([target]) as (tmp,):
            tmp.mkdir()
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write([target], force=True) as (tmp,):
            (tmp / "c").mkdir(parents=True)
            raise RuntimeError("boom")
    assert (target / "c" / "0").read_text() == "first"
    with atomic_write([target], force=True) as (tmp,):
        tmp.mkdir()
        (tmp / "new").write_text("second")
    assert sorted(p.name for p in target.iterdir()) == ["new"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["labels.zarr"]
    (tmp_path / "plain").mkdir()
    with pytest.raises(IsADirectoryError, match="is a folder"):
        with atomic_write([tmp_path / "plain"], force=True) as (tmp,):
            pass
