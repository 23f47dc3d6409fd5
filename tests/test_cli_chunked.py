"""``segment --model`` on Zarr and memory-mapped images, chunk by chunk, and its refusals."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest
import zarr

from napari_swa_imesh._zarr_io import open_lazy, open_levels
from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import (
    RecommendedModel,
    load_model,
    samples_from_truth,
    save_samples,
)
from swa_cli_helpers import run


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("chunked")
    image, truth = tissue_phantom((40, 48, 48), noise=0.06, bias=0.3, spacing=(1, 1, 1))
    RecommendedModel().fit(image, samples_from_truth(truth)).save(folder / "m.npz")
    save_samples(samples_from_truth(truth), folder / "s.json")
    np.save(folder / "img.npy", image)
    z = zarr.create_array(str(folder / "img.zarr"), shape=image.shape, chunks=(16, 16, 16),
                          dtype=image.dtype, attributes={"spacing": [2.0, 1.0, 0.5]})
    z[:] = image
    return folder


def run_fresh(*argv):
    """The command in its own process: a budget counts what the process holds, and the
    test runner's own memory (over 1 GB late in a full run) is not the command's."""
    done = subprocess.run([sys.executable, "-m", "napari_swa_imesh.cli", *map(str, argv)],
                          capture_output=True, text=True, timeout=600)
    return done.returncode, done.stdout, done.stderr


def test_zarr_in_zarr_out_equals_the_in_memory_run(scene, capsys, tmp_path):
    code, _, _ = run(capsys, "segment", scene / "img.npy", "--model", scene / "m.npz",
                     "-o", tmp_path / "ref.npy")
    assert code == 0
    code, out, err = run_fresh("segment", scene / "img.zarr", "--model", scene / "m.npz",
                               "-o", tmp_path / "lab.zarr", "--memory", "1GB", "--json")
    assert code == 0, err
    summary = json.loads(out)
    ref = np.load(tmp_path / "ref.npy")
    store = zarr.open_array(str(tmp_path / "lab.zarr"), mode="r")
    np.testing.assert_array_equal(store[:], ref)
    assert store.dtype == np.uint8 and store.attrs["spacing"] == [2.0, 1.0, 0.5]
    assert summary["chunked"] and summary["plan"]["halo"] == 7
    # volumes: voxel counts times the voxel size (1 mm^3 here)
    for label, v in summary["volumes"].items():
        assert v["voxels"] == int((ref == int(label)).sum()) and v["volume"] == v["voxels"]
    assert [p.name for p in tmp_path.iterdir()] != [] and not any(
        p.name.startswith(".swa-imesh-") for p in tmp_path.iterdir())


def test_memory_mapped_npy_with_a_budget_writes_any_label_format(scene, capsys, tmp_path):
    code, _, _ = run(capsys, "segment", scene / "img.npy", "--model", scene / "m.npz",
                     "-o", tmp_path / "ref.npy")
    code, out, err = run_fresh("segment", scene / "img.npy", "--model", scene / "m.npz",
                               "-o", tmp_path / "lab.tif", "--memory", "800MB")
    assert code == 0 and "chunk by chunk" in out, err
    import tifffile

    np.testing.assert_array_equal(tifffile.imread(tmp_path / "lab.tif"),
                                  np.load(tmp_path / "ref.npy"))


@pytest.mark.parametrize("image,extra", [("img.zarr", []), ("img.npy", ["--memory", "1GB"])])
def test_fit_on_the_boxes_of_a_store_equals_the_in_memory_fit(scene, capsys, tmp_path,
                                                              image, extra, monkeypatch):
    from napari_swa_imesh.segmentation import _recommended

    # a store's fit keeps the boxes' means (the interiors' means need the whole image,
    # _refine_em): compare with the in-memory fit without that step
    with monkeypatch.context() as patch:
        patch.setattr(_recommended, "refine_fitted", lambda m, s: {"applied": False})
        code, _, _ = run(capsys, "segment", scene / "img.npy", "--samples", scene / "s.json",
                         "-o", tmp_path / "ref.npy", "--model-out", tmp_path / "ref.npz")
    assert code == 0
    code, out, err = run_fresh("segment", scene / image, "--samples", scene / "s.json",
                               "-o", tmp_path / "lab.zarr", "--model-out", tmp_path / "m.npz",
                               "--json", *extra)
    assert code == 0, err
    summary = json.loads(out)
    ref = np.load(tmp_path / "ref.npy")
    labels = zarr.open_array(str(tmp_path / "lab.zarr"), mode="r")[:]
    inner = tuple(slice(8, n - 8) for n in ref.shape)
    assert (labels[inner] == ref[inner]).mean() >= 0.995
    assert summary["chunked"] and summary["fit"]["bias_correction"] == load_model(
        tmp_path / "ref.npz").bias_correction
    # the saved model is the one that labelled the store
    code, _, _ = run(capsys, "segment", scene / "img.npy", "--model", tmp_path / "m.npz",
                     "-o", tmp_path / "again.npy")
    np.testing.assert_array_equal(np.load(tmp_path / "again.npy"), labels)


def test_reference_model_on_a_store_equals_the_in_memory_run(scene, capsys, tmp_path):
    code, _, _ = run(capsys, "segment", scene / "img.npy", "--samples", scene / "s.json",
                     "--method", "reference", "--scale", 1, "-o", tmp_path / "ref.npy",
                     "--model-out", tmp_path / "ref.npz")
    assert code == 0
    code, out, err = run_fresh("segment", scene / "img.zarr", "--model", tmp_path / "ref.npz",
                               "-o", tmp_path / "lab.zarr", "--memory", "1GB", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["chunked"] and summary["plan"]["halo"] == 0
    assert all(c % 2 == 0 for c in summary["plan"]["chunks"])
    np.testing.assert_array_equal(zarr.open_array(str(tmp_path / "lab.zarr"), mode="r")[:],
                                  np.load(tmp_path / "ref.npy"))


def test_existing_store_needs_force_and_is_replaced_whole(scene, capsys, tmp_path):
    out = tmp_path / "lab.zarr"
    assert run(capsys, "segment", scene / "img.zarr", "--model", scene / "m.npz",
               "-o", out)[0] == 0
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    code, _, err = run(capsys, "segment", scene / "img.zarr", "--model", scene / "m.npz",
                       "-o", out)
    assert code == 2 and "already exists" in err and err.count("\n") == 1
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    (out / "stray").write_text("from an older run")
    assert run(capsys, "segment", scene / "img.zarr", "--model", scene / "m.npz",
               "-o", out, "--force")[0] == 0
    assert not (out / "stray").exists() and sorted(
        p.relative_to(out) for p in out.rglob("*")) == before
    assert [p.name for p in tmp_path.iterdir()] == ["lab.zarr"]


@pytest.mark.parametrize("case,message", [
    ("group", "is a Zarr group, not an array or an OME-Zarr image"),
    ("budget", "more than the budget of 0.05 GB; give more memory"),
    ("sieve", "--sieve need.s. the whole image in memory"),
    ("samples", "the reference method fits in memory; segment this image with the "
                "recommended method"),
    ("nothing", "no Zarr store at"),
])
def test_bad_input_exits_2_and_leaves_nothing(scene, capsys, tmp_path, case, message):
    image, extra = scene / "img.zarr", []
    if case == "group":
        g = zarr.open_group(str(tmp_path / "grp.zarr"), mode="w")
        g.create_array("data", shape=(4, 4), dtype="f4")
        image = tmp_path / "grp.zarr"
    elif case == "budget":
        extra = ["--memory", "50MB"]
    elif case == "sieve":
        extra = ["--sieve", "5"]
    elif case == "nothing":
        image = tmp_path / "missing.zarr"
    before = sorted(tmp_path.iterdir())
    source = ["--samples", scene / "s.json", "--method", "reference"] if case == "samples" else [
        "--model", scene / "m.npz"]
    code, _, err = run(capsys, "segment", image, *source, "-o", tmp_path / "lab.zarr",
                       *extra)
    assert code == 2
    assert re.search(message, err) and err.count("\n") == 1
    assert sorted(tmp_path.iterdir()) == before


def test_ome_zarr_levels_and_spacing(tmp_path):
    root = zarr.open_group(str(tmp_path / "img.ome.zarr"), mode="w", zarr_format=2)
    data = np.arange(2 * 8 * 12, dtype=np.float32).reshape(1, 2, 8, 12)
    root.create_array("0", data=data[..., :, :, :], chunks=(1, 2, 4, 4))
    root.create_array("1", data=data[..., ::2, ::2].copy(), chunks=(1, 2, 4, 4))
    root.attrs["multiscales"] = [{
        "version": "0.4",
        "axes": [{"name": "c", "type": "channel"}, {"name": "z", "type": "space"},
                 {"name": "y", "type": "space"}, {"name": "x", "type": "space"}],
        "datasets": [
            {"path": "0", "coordinateTransformations": [
                {"type": "scale", "scale": [1, 3.0, 0.5, 0.5]}]},
            {"path": "1", "coordinateTransformations": [
                {"type": "scale", "scale": [1, 3.0, 1.0, 1.0]}]}]}]
    levels, spacing = open_levels(tmp_path / "img.ome.zarr")
    assert [lv.shape for lv in levels] == [(2, 8, 12), (2, 4, 6)]
    assert spacing == (3.0, 0.5, 0.5)
    np.testing.assert_array_equal(levels[1].compute(), data[0, :, ::2, ::2])
    two = zarr.open_group(str(tmp_path / "two.ome.zarr"), mode="w", zarr_format=2)
    two.create_array("0", data=np.zeros((2, 2, 4, 4), np.float32))
    two.attrs["multiscales"] = root.attrs["multiscales"]
    with pytest.raises(ValueError, match=r"holds \[2\] channels or time points"):
        open_levels(tmp_path / "two.ome.zarr")


def test_npy_is_read_block_by_block(tmp_path):
    data = np.asfortranarray(np.arange(5 * 6 * 7, dtype=np.int16).reshape(5, 6, 7))
    np.save(tmp_path / "a.npy", data)
    lazy, spacing = open_lazy(tmp_path / "a.npy", chunks=(2, 3, 4))
    assert lazy.numblocks == (3, 2, 2) and spacing == (1.0, 1.0, 1.0)
    np.testing.assert_array_equal(lazy.compute(), data)


def test_res_on_a_store_reads_the_boxes_only_and_equals_the_loaded_image(scene, capsys,
                                                                         tmp_path):
    import tifffile

    from napari_swa_imesh.segmentation import load_samples
    from napari_swa_imesh.segmentation._res import res_statistics, res_statistics_of_boxes

    image = np.load(scene / "img.npy")
    tifffile.imwrite(tmp_path / "img.tif", image)
    truth = tissue_phantom((40, 48, 48), noise=0.06, bias=0.3, spacing=(1, 1, 1))[1]
    samples = samples_from_truth(truth)
    save_samples(samples, tmp_path / "s.json")
    results = []
    for name in ("img.zarr", "img.npy"):
        code, out, err = run(capsys, "res", scene / name, "--samples", tmp_path / "s.json",
                             "--json")
        assert code == 0, err
        results.append(json.loads(out))
    code, out, err = run(capsys, "res", tmp_path / "img.tif", "--samples", tmp_path / "s.json",
                         "--json")
    assert code == 0, err
    loaded = json.loads(out)
    for r in results:
        for key in ("suggested_scale", "materials"):
            assert r[key] == loaded[key]
    # the library call on a memory-mapped array reads the boxes, not the volume
    import tracemalloc

    # (the phantom in the corner of a 32 MB volume that is never read)
    big = np.lib.format.open_memmap(tmp_path / "big.npy", mode="w+", dtype=np.float32,
                                    shape=(160, 224, 224))
    big[:40, :48, :48] = image
    big.flush()
    del big
    mapped = np.load(tmp_path / "big.npy", mmap_mode="r")
    tracemalloc.start()
    lazy = res_statistics_of_boxes(mapped, load_samples(tmp_path / "s.json"))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    full = res_statistics(image, load_samples(tmp_path / "s.json"))
    np.testing.assert_array_equal(lazy.mean, full.mean)
    np.testing.assert_array_equal(lazy.n_tiles, full.n_tiles)
    assert peak < mapped.nbytes / 20


def test_res_on_a_store_refuses_nan_in_a_box(scene, capsys, tmp_path):
    image = np.load(scene / "img.npy").copy()
    truth = tissue_phantom((40, 48, 48), noise=0.06, bias=0.3, spacing=(1, 1, 1))[1]
    samples = samples_from_truth(truth)
    save_samples(samples, tmp_path / "s.json")
    box = samples.boxes[0]
    image[tuple(slice(s.start, s.start + 1) for s in box.slices)] = np.nan
    z = zarr.create_array(str(tmp_path / "nan.zarr"), shape=image.shape, chunks=(16, 16, 16),
                          dtype=image.dtype)
    z[:] = image
    code, _, err = run(capsys, "res", tmp_path / "nan.zarr", "--samples", tmp_path / "s.json")
    assert code == 2 and "NaN or infinity" in err and err.count("\n") == 1
