"""The accuracy page of benchmarks/bench_accuracy.py (benchmarks/accuracy_report.py): the
issue-25 goal is judged per variant, and a bad --markdown path stops before any work."""

import os
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))
import accuracy_report as R  # noqa: E402 (benchmarks/ is put on sys.path just above)

NAMES = ["recommended", "bias off", R.PEER]


def _runs(*dice):
    return [({1: c, 2: g, 3: w}, 1.0) for c, g, w in dice]


def _out(rec, peer):
    return {("v", "recommended"): _runs(*rec), ("v", "bias off"): _runs(*rec),
            ("v", R.PEER): _runs(*peer)}


def test_goal_met_only_when_gm_wm_reach_the_peer_and_csf_the_floor():
    row = R.generator_rows("held-out", _out([(0.85, 0.95, 0.94)], [(0.9, 0.95, 0.93)]),
                           ["v"], str, NAMES)
    assert row == [("| held-out | v | .850 / .950 / .940 | .850 / .950 / .940 | "
                    ".900 / .950 / .930 | met |")]
    # the mean over cases is judged, not each case
    row = R.generator_rows("h", _out([(0.85, 0.96, 0.90), (0.85, 0.94, 0.96)],
                                     [(0.9, 0.95, 0.92)]), ["v"], str, NAMES)[0]
    assert row.endswith("| met |") and ".850 / .950 / .930" in row
    row = R.generator_rows("h", _out([(0.79, 0.949, 0.94)], [(0.9, 0.95, 0.93)]),
                           ["v"], str, NAMES)[0]
    assert row.endswith("| **CSF < 0.80, GM < peer** |")


def test_page_has_one_row_per_variant_under_the_header():
    lines = R.generator_rows("h", _out([(0.9, 0.9, 0.9)], [(0.9, 0.9, 0.9)]), ["v"], str,
                             NAMES)
    page = R.markdown_page(lines, NAMES, [], "python benchmarks/bench_accuracy.py")
    table = [ln for ln in page.splitlines() if ln.startswith("|")]
    assert table[0] == "| generator | variant | " + " | ".join(NAMES) + " | goal |"
    assert table[2:] == lines and "Texture mosaics" not in page


def test_bad_markdown_path_exits_2_before_any_work(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).resolve().parents[1] / "src"), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, str(BENCH / "bench_accuracy.py"), "--only-anatomy",
                          "--markdown", str(tmp_path / "missing" / "accuracy.md")],
                         capture_output=True, text=True, env=env, timeout=120,
                         check=False)
    assert out.returncode == 2
    assert "does not exist; create it" in out.stderr and out.stdout == ""
