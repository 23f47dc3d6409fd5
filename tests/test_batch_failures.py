"""``batch`` when workers die, images are corrupt or the output folder is new (issue 22)."""

from __future__ import annotations

import logging
import warnings

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.pipeline import _batch
from napari_swa_imesh.segmentation import RecommendedModel, samples_from_truth
from swa_cli_helpers import run


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cohort")
    image, truth = tissue_phantom((16, 24, 24), noise=0.05, spacing=(1, 1, 1))
    with warnings.catch_warnings():     # small boxes limit the scales: not the point here
        warnings.simplefilter("ignore", UserWarning)
        RecommendedModel().fit(image, samples_from_truth(truth)).save(folder / "m.npz")
    np.save(folder / "scan.npy", image)
    (folder / "corrupt.npy").write_text("not an array")
    return folder


def _hidden(folder):
    return [p for p in folder.rglob(".swa-imesh*")]


def test_a_worker_killed_after_writing_does_not_fail_the_image(cohort, tmp_path,
                                                               monkeypatch):
    from distributed import Client, LocalCluster

    import batch_dying_task

    monkeypatch.setattr(_batch, "segment_one", batch_dying_task.segment_then_die_once)
    out = tmp_path / "run" / "out"
    out.mkdir(parents=True)
    with _batch.quiet_dask(), LocalCluster(n_workers=1, threads_per_worker=1,
                                           processes=True, dashboard_address=None,
                                           silence_logs=logging.CRITICAL) as cluster, \
            Client(cluster) as client:
        (row,) = _batch.run_batch([cohort / "scan.npy"], cohort / "m.npz", out,
                                  client=client, retries=0)
    assert (tmp_path / "run" / "first-try-done").exists()        # the worker did die
    assert "error" not in row, row
    assert row["output"] == str(out / "scan_labels.npy")
    alone = tmp_path / "alone.npy"
    assert main(["segment", str(cohort / "scan.npy"), "--model", str(cohort / "m.npz"),
                 "-o", str(alone)]) == 0
    np.testing.assert_array_equal(np.load(out / "scan_labels.npy"), np.load(alone))
    assert sorted(p.name for p in out.iterdir()) == ["scan_labels.npy"]


def test_a_retry_keeps_equal_outputs_and_refuses_other_ones(cohort, tmp_path):
    out = tmp_path / "scan_labels.npy"
    first = _batch.segment_one(str(cohort / "scan.npy"), str(cohort / "m.npz"), str(out))
    kept = out.stat().st_ino
    again = _batch.segment_one(str(cohort / "scan.npy"), str(cohort / "m.npz"), str(out))
    assert "error" not in again and again["volumes"] == first["volumes"]
    assert out.stat().st_ino == kept and _hidden(tmp_path) == []
    np.save(out, np.zeros((16, 24, 24), np.uint8))                # someone else's labels
    row = _batch.segment_one(str(cohort / "scan.npy"), str(cohort / "m.npz"), str(out))
    assert "appeared while this batch ran and holds other labels" in row["error"]
    assert not np.load(out).any() and _hidden(tmp_path) == []


def test_a_corrupt_image_is_not_retried(cohort, tmp_path, monkeypatch):
    from distributed import Client, LocalCluster

    tries = []
    real = _batch._segment_one

    def counted(*args, **kwargs):
        tries.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(_batch, "_segment_one", counted)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        (row,) = _batch.run_batch([cohort / "corrupt.npy"], cohort / "m.npz", tmp_path,
                                  client=client, retries=3)
    assert len(tries) == 1
    # the reader's one sentence about the damaged file, not a retry's or dask's text
    assert row["error"].startswith("corrupt.npy is not a .npy file") and "\n" not in row["error"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("error,tries", [(OSError(28, "the disk is full"), 1),
                                         (OSError("a flaky network disk"), 3)])
def test_only_errors_that_may_pass_are_retried(cohort, tmp_path, monkeypatch, error, tries):
    from distributed import Client, LocalCluster

    seen = []

    def failing(*args, **kwargs):
        seen.append(1)
        raise error

    monkeypatch.setattr(_batch, "_segment_one", failing)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        (row,) = _batch.run_batch([cohort / "scan.npy"], cohort / "m.npz", tmp_path,
                                  client=client, retries=2)
    assert len(seen) == tries and str(error.args[-1]) in row["error"]


def test_a_cluster_that_does_not_start_is_one_sentence(cohort, tmp_path, capsys,
                                                         monkeypatch):
    import distributed

    def nanny_fails(*args, **kwargs):
        logging.getLogger("distributed.nanny").error("Failed to start process\nTraceback")
        raise RuntimeError("Nanny failed to start.\nmore lines")

    monkeypatch.setattr(distributed, "LocalCluster", nanny_fails)
    code, out, err = run(capsys, "batch", "--model", cohort / "m.npz",
                         "-o", tmp_path / "new" / "out", cohort / "scan.npy")
    assert code == 2 and err.count("\n") == 1, err
    assert "the local Dask cluster of 1 worker(s) did not start" in err
    assert "RuntimeError: Nanny failed to start." in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []                       # the new folders are gone


def test_the_output_folder_is_made_after_the_checks(cohort, tmp_path, capsys):
    target = tmp_path / "new" / "out"
    code, _, err = run(capsys, "batch", "--model", cohort / "m.npz", "-o", target,
                       "--workers", "0", cohort / "scan.npy")
    assert code == 2 and "--workers must be 1 or more" in err
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    code, _, err = run(capsys, "batch", "--model", cohort / "m.npz",
                       "-o", tmp_path / "file" / "out", cohort / "scan.npy")
    assert code == 2 and "is a file, not a folder" in err
    code, _, err = run(capsys, "batch", "--model", cohort / "m.npz", "-o", target,
                       "--workers", "1", cohort / "scan.npy")
    assert code == 0, err
    assert [p.name for p in target.iterdir()] == ["scan_labels.npy"]


def test_quiet_dask_silences_distributed_and_restores_it(capfd):
    log = logging.getLogger("distributed.scheduler")
    before = logging.getLogger("distributed").level
    handler = logging.StreamHandler()
    log.addHandler(handler)
    try:
        with _batch.quiet_dask():
            log.error("a multi-line\ntraceback")
        assert capfd.readouterr().err == ""
        assert logging.getLogger("distributed").level == before
        log.error("heard")
        assert "heard" in capfd.readouterr().err
    finally:
        log.removeHandler(handler)
