"""The byte budget (issue 26): the estimate against measured peaks, the heap released
between phases, and the refusal of a run that does not fit.

No timing is asserted; the one measured peak is a subprocess's own (``VmHWM``).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from benchmarks._peak import PEAK_SOURCE
from simulate_cases import blobs

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import _budget, _release
from napari_swa_imesh.simulate._budget import check_memory, estimate_memory
from napari_swa_imesh.simulate._release import release_memory
from swa_cli_helpers import run as _run


def test_release_memory_returns_and_never_raises(monkeypatch):
    """On glibc it trims; where the C library has no malloc_trim, or the call fails, it
    is a no-op that says so."""
    assert release_memory() in (True, False)
    assert release_memory() in (True, False)              # the look-up is cached
    monkeypatch.setattr(_release, "_TRIM", [None])          # musl, macOS, Windows
    assert release_memory() is False

    def broken(_pad):
        raise OSError("no heap")

    monkeypatch.setattr(_release, "_TRIM", [broken])
    assert release_memory() is False


def test_release_memory_finds_glibc_malloc_trim_on_linux():
    import ctypes.util

    if not sys.platform.startswith("linux") or ctypes.util.find_library("c") is None:
        pytest.skip("glibc's malloc_trim is a Linux matter")
    import platform

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("not glibc")
    assert release_memory() is True


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("interval", [False, True])
def test_the_estimate_grows_with_the_mesh(order, interval):
    meshes = [mesh_labels(blobs((n, n, n), seed=3)) for n in (5, 8, 11)]
    assert meshes[0].n_cells < meshes[1].n_cells < meshes[2].n_cells
    estimates = [estimate_memory(m, order, interval) for m in meshes]
    assert estimates == sorted(estimates) and len(set(estimates)) == 3


def test_the_half_storage_estimate_is_above_every_measured_peak():
    """The fitted P2 constants against the peaks they were fitted to (the whole command's
    RSS, `MEASURED_HALF`): above each, and by no more than the margin plus the fit's
    slack at the largest, where an overestimate refuses runs that fit."""
    for unknowns, cells, peak in _budget.MEASURED_HALF:
        estimate = (_budget.BYTES_HALF_FIXED + _budget.BYTES_PER_UNKNOWN_HALF[3] * unknowns
                    + _budget.BYTES_PER_CELL[3] * cells)
        assert estimate >= peak, (unknowns, estimate, peak)
    unknowns, cells, peak = max(_budget.MEASURED_HALF)
    estimate = (_budget.BYTES_HALF_FIXED + _budget.BYTES_PER_UNKNOWN_HALF[3] * unknowns
                + _budget.BYTES_PER_CELL[3] * cells)
    assert estimate <= 1.15 * peak


def test_the_interval_estimate_is_above_the_measured_peaks_with_the_dual():
    """3-D P2 with the interval (the dual's facets dominate): above each measured peak."""
    for cells, unknowns, peak in _budget.MEASURED_DUAL:
        facets = 4 * cells / 2
        dual = _budget.BYTES_PER_FACET[3] * facets + 8 * unknowns
        primal = _budget.BYTES_HALF_FIXED + _budget.BYTES_PER_UNKNOWN_HALF[3] * unknowns
        assert max(primal, dual) + _budget.BYTES_PER_CELL[3] * cells >= peak


# the child's own peak (benchmarks/_peak.py: VmHWM, not the ru_maxrss it inherits)
CHILD = PEAK_SOURCE + (
    "import json, sys\n"
    "from napari_swa_imesh.cli import main\n"
    "rc = main(sys.argv[1:])\n"
    "sys.stdout.flush()\n"
    "print('PEAK ' + json.dumps(peak_bytes()), file=sys.stderr)\n"
)


def test_the_estimate_is_above_a_measured_small_peak(tmp_path):
    """A small P2 run in a fresh process: its peak RSS (interpreter included) is below
    the estimate the command printed for it."""
    np.save(tmp_path / "blobs.npy", blobs((12, 12, 12), seed=4))
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, "simulate", str(tmp_path / "blobs.npy"),
         "-k", "1=1", "2=10", "3=0.1", "--axes", "x", "--order", "2", "--adapt", "0",
         "--no-interval", "--json"], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout)
    line = [ln for ln in proc.stderr.splitlines() if ln.startswith("PEAK ")][-1]
    peak = json.loads(line[5:])
    assert 0 < peak <= report["memory_estimate_bytes"]


def test_a_run_above_the_budget_is_refused_in_one_sentence(tmp_path, capsys):
    mesh = mesh_labels(blobs((6, 6, 6), seed=2))
    need = estimate_memory(mesh, 2, False)
    assert check_memory(mesh, 2, False, need, asked=True) is None
    with pytest.raises(ValueError) as refused:
        check_memory(mesh, 2, False, need - 1, asked=True)
    message = str(refused.value)
    assert message.count(". ") == 0 and message.endswith(".") and "\n" not in message
    assert "needs about" in message and "--memory" in message
    # the command line: exit 2 and that sentence, before anything is assembled
    np.save(tmp_path / "blobs.npy", blobs((6, 6, 6), seed=2))
    rc, out, err = _run(capsys, "simulate", tmp_path / "blobs.npy", "-k", "1=1", "2=10",
                        "3=0.1", "--order", "2", "--memory", "1k")
    assert rc == 2 and out == ""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "above the memory budget" in lines[0]
    assert lines[0].rstrip().endswith(".")
