"""``swa-imesh batch``: a cohort on a dask.distributed LocalCluster equals one-by-one runs."""

import json
import re
import time

import numpy as np
import pytest

from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.io import write_labels
from napari_swa_imesh.pipeline._batch import expand_inputs
from napari_swa_imesh.segmentation import RecommendedModel, samples_from_truth
from swa_cli_helpers import run


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cohort")
    image, truth = tissue_phantom((24, 32, 32), noise=0.05, spacing=(1, 1, 1))
    RecommendedModel().fit(image, samples_from_truth(truth)).save(folder / "m.npz")
    (folder / "in").mkdir()
    for i in range(3):
        img, _ = tissue_phantom((24, 32, 32), noise=0.05, bias=0.2, seed=i + 1,
                                spacing=(1, 1, 1))
        np.save(folder / "in" / f"scan{i:02d}.npy", img)
    write_labels(folder / "in" / "flat.tif", np.full((24, 32, 32), 7, np.uint8))
    return folder


def test_batch_equals_one_by_one_runs_and_reports_each_image(cohort, capsys, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    code, text, err = run(capsys, "batch", "--model", cohort / "m.npz", "-o", out,
                          cohort / "in", "--workers", 2, "--json")
    assert code == 2                      # flat.tif holds one value: refused, the rest run
    assert "1 of 4 images failed (flat.tif: the image holds one value everywhere" in err
    summary = json.loads(text)
    rows = {r["image"].rsplit("/", 1)[-1]: r for r in summary["images"]}
    assert summary["workers"] == 2 and set(rows) == {"flat.tif", "scan00.npy",
                                                     "scan01.npy", "scan02.npy"}
    assert "error" in rows["flat.tif"] and not (out / "flat_labels.tif").exists()
    for i in range(3):
        name = f"scan{i:02d}"
        assert run(capsys, "segment", cohort / "in" / f"{name}.npy", "--model",
                   cohort / "m.npz", "-o", tmp_path / f"{name}.npy")[0] == 0
        alone = np.load(tmp_path / f"{name}.npy")
        batch = np.load(out / f"{name}_labels.npy")
        np.testing.assert_array_equal(batch, alone)
        row = rows[f"{name}.npy"]
        assert row["output"].endswith(f"{name}_labels.npy") and row["seconds"] > 0
        assert {int(k): v["voxels"] for k, v in row["volumes"].items()} == {
            k: int((alone == k).sum()) for k in (1, 2, 3)}
    assert sorted(p.name for p in out.iterdir()) == [f"scan{i:02d}_labels.npy"
                                                     for i in range(3)]


def test_existing_outputs_unknown_schedulers_and_twins_exit_2(cohort, capsys, tmp_path):
    np.save(tmp_path / "scan00_labels.npy", np.zeros(3))
    code, _, err = run(capsys, "batch", "--model", cohort / "m.npz", "-o", tmp_path,
                       cohort / "in" / "scan0*.npy")
    assert code == 2 and "scan00_labels.npy already exists" in err
    t0 = time.perf_counter()
    code, _, err = run(capsys, "batch", "--model", cohort / "m.npz", "-o", tmp_path,
                       "--force", cohort / "in" / "scan01.npy",
                       "--scheduler", "tcp://127.0.0.1:9")
    assert code == 2 and "no Dask scheduler answers at tcp://127.0.0.1:9 within 5 s" in err
    assert time.perf_counter() - t0 < 30
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan00_labels.npy"]
    (tmp_path / "b").mkdir()
    np.save(tmp_path / "b" / "scan01.npy", np.zeros((4, 4)))
    with pytest.raises(ValueError, match="would both write scan01_labels"):
        expand_inputs([cohort / "in" / "scan01.npy", tmp_path / "b"])
    with pytest.raises(FileNotFoundError, match="holds no image"):
        expand_inputs([str(tmp_path / "nothing*.npy")])


def test_batch_meshes_each_image_in_its_frame(cohort, capsys, tmp_path):
    import meshio

    code, text, _ = run(capsys, "batch", "--model", cohort / "m.npz", "-o", tmp_path,
                        cohort / "in" / "scan01.npy", "--mesh", ".vtu", "--json",
                        "--workers", 1)
    assert code == 0
    (row,) = json.loads(text)["images"]
    mesh = meshio.read(tmp_path / "scan01_mesh.vtu")
    assert row["mesh"]["cells"] == len(mesh.cells[0].data) > 0
    labels = np.load(tmp_path / "scan01_labels.npy")
    # every voxel is meshed: the tetrahedra fill the 24 x 32 x 32 box of unit voxels
    p = mesh.points[mesh.cells[0].data]
    volume = np.abs(np.linalg.det(p[:, 1:] - p[:, :1])).sum() / 6
    assert volume == pytest.approx(labels.size)
    for material in (1, 2, 3):
        cells = mesh.cell_data["material"][0] == material
        got = np.abs(np.linalg.det(p[cells, 1:] - p[cells, :1])).sum() / 6
        assert got == pytest.approx(row["volumes"][str(material)]["volume"])


def test_batch_simulates_each_image_as_one_by_one_simulate_runs(cohort, capsys, tmp_path):
    images = [cohort / "in" / f"scan0{i}.npy" for i in (0, 1)]
    code, text, _ = run(capsys, "batch", "--model", cohort / "m.npz", "-o", tmp_path,
                        *images, "--simulate", "-k", "1=1", "2=10", "3=0.1", "--json",
                        "--workers", 2)
    assert code == 0
    rows = {r["image"].rsplit("/", 1)[-1]: r for r in json.loads(text)["images"]}
    seen = set()
    for name in ("scan00", "scan01"):
        code, alone, _ = run(capsys, "simulate", tmp_path / f"{name}_labels.npy", "-k", "1=1",
                             "2=10", "3=0.1", "--json")
        assert code == 0
        alone = json.loads(alone)
        got = rows[f"{name}.npy"]["simulate"]
        # one solve, up to the summation order of a single- vs a multi-threaded BLAS
        assert got["k_eff"] == pytest.approx(alone["k_eff"], rel=1e-12)
        assert set(got["k_eff"]) == {"x", "y", "z"}
        assert got["volume_fractions"] == alone["volume_fractions"]
        seen.add(tuple(got["k_eff"].values()))
    assert len(seen) == 2                        # two images, two answers
@pytest.mark.parametrize("extra,message", [
    (["--simulate"], "--simulate needs --conductivity MATERIAL=K"),
    (["-k", "1=1"], "--simulate needs --conductivity"),
    (["--simulate", "-k", "1=1", "2=10"], "material 3 .material 3. has no conductivity"),
    (["--simulate", "-k", "1=1", "2=1", "3=1", "9=1"], "names material 9, which is not in"),
])
def test_batch_simulate_checks_conductivities_before_any_work(cohort, capsys, tmp_path,
                                                              extra, message):
    code, _, err = run(capsys, "batch", "--model", cohort / "m.npz", "-o", tmp_path,
                       cohort / "in" / "scan00.npy", *extra)
    assert code == 2 and re.search(message, err) and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_zarr_inputs_are_labelled_chunk_by_chunk_on_the_workers(cohort, capsys, tmp_path):
    import zarr

    image = np.load(cohort / "in" / "scan02.npy")
    z = zarr.create_array(str(tmp_path / "scan02.zarr"), shape=image.shape,
                          chunks=(8, 16, 16), dtype=image.dtype)
    z[:] = image
    (tmp_path / "out").mkdir()
    code, text, _ = run(capsys, "batch", "--model", cohort / "m.npz", "-o", tmp_path / "out",
                        tmp_path / "scan02.zarr", "--workers", 1, "--json")
    assert code == 0
    (row,) = json.loads(text)["images"]
    assert row["chunked"] and row["output"].endswith("scan02_labels.zarr")
    assert run(capsys, "segment", cohort / "in" / "scan02.npy", "--model", cohort / "m.npz",
               "-o", tmp_path / "alone.npy")[0] == 0
    np.testing.assert_array_equal(
        zarr.open_array(str(tmp_path / "out" / "scan02_labels.zarr"), mode="r")[:],
        np.load(tmp_path / "alone.npy"))


def test_summary_table_lists_file_seconds_and_volumes():
    from napari_swa_imesh.pipeline._cli import _batch_table

    rows = [{"image": "/d/a.npy", "output": "/o/a_labels.npy", "seconds": 1.234,
             "volumes": {1: {"voxels": 10, "volume": 20.0}, 3: {"voxels": 1, "volume": 2.0}}},
            {"image": "/d/b.tif", "output": "/o/b_labels.tif", "error": "bad"}]
    lines = _batch_table(rows).splitlines()
    assert lines[0].split() == ["image", "labels", "seconds", "volume", "1", "volume", "3"]
    assert lines[1].split() == ["a.npy", "a_labels.npy", "1.23", "20", "2"]
    assert lines[2].split() == ["b.tif", "b_labels.tif", "failed"]
    rows[0]["simulate"] = {"k_eff": {"x": 1.5, "y": 2.25}}
    lines = _batch_table(rows).splitlines()
    assert lines[0].split()[-4:] == ["k_eff", "x", "k_eff", "y"]
    assert lines[1].split()[-2:] == ["1.5", "2.25"] and lines[2].split()[-1] == "failed"


def test_the_scheduler_retries_a_failed_image(cohort, tmp_path, monkeypatch):
    from distributed import Client, LocalCluster

    from napari_swa_imesh.pipeline import _batch

    log = tmp_path / "tries.txt"           # the task is pickled: count on disk
    real = _batch.segment_one

    def flaky(image, *args, **kwargs):      # a worker lost once, as on a busy cluster
        with open(log, "a") as fh:
            fh.write("try\n")
        if log.read_text().count("try") == 1:
            raise OSError("worker lost")
        return real(image, *args, **kwargs)

    monkeypatch.setattr(_batch, "segment_one", flaky)
    image = cohort / "in" / "scan00.npy"
    (tmp_path / "out").mkdir()
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        (row,) = _batch.run_batch([image], cohort / "m.npz", tmp_path / "out",
                                  client=client, retries=1)
        assert "error" not in row and log.read_text().count("try") == 2
        log.unlink()
        (row,) = _batch.run_batch([image], cohort / "m.npz", tmp_path / "out",
                                  client=client, retries=0, force=True)
        assert row["error"] == "worker lost" and log.read_text().count("try") == 1
