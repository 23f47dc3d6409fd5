"""The tasks' own timings in a block-wise report (what the weak-scaling benchmark reads
to judge scaling independently of the machine's load)."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.mesh.blocks import mesh_blocks
from napari_swa_imesh.mesh.blocks._timing import task_report


def test_task_report_sums_per_worker_and_round():
    r = task_report({"coarse": [(7, 0.0, 1.0, 0.5)],
                     "mesh": [(7, 1.0, 3.0, 1.5), (8, 1.0, 2.0, 1.0), (8, 2.0, 3.0, 0.25)]}, 2)
    by_pid = {w["pid"]: w for w in r["workers"]}
    assert by_pid[7] == {"pid": 7, "tasks": 2, "busy_s": 3.0, "cpu_s": 2.0}
    assert by_pid[8] == {"pid": 8, "tasks": 2, "busy_s": 2.0, "cpu_s": 1.25}
    assert r["rounds"]["mesh"] == {"span_s": 2.0, "busy_s": 4.0, "cpu_s": 2.75,
                                   "busy_fraction": 1.0}
    assert r["rounds"]["coarse"]["busy_fraction"] == pytest.approx(0.5)   # one of two idle
    assert task_report({"mesh": []}, 1)["rounds"] == {}


def test_the_report_carries_every_task(tmp_path):
    lab = np.ones((12, 10, 14), np.int64)
    lab[:, :, 7:] = 2
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=4, workers=0)
    tasks = report["tasks"]
    assert tasks["n_workers"] == 1 and len(tasks["workers"]) == 1    # this process
    assert tasks["workers"][0]["tasks"] == 2 * report["blocks"]      # two rounds
    assert set(tasks["rounds"]) == {"coarse", "mesh"}
    for r in tasks["rounds"].values():
        assert 0 < r["busy_fraction"] <= 1 + 1e-9 and r["cpu_s"] >= 0
    assert tasks["client_cpu_s"] >= tasks["rounds"]["mesh"]["cpu_s"] - 1e-6  # ran here
