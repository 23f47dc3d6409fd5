"""``swa-imesh simulate --stochastic``: the door, the run, the files (issue 28, part 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from napari_swa_imesh.simulate import stochastic_k_eff
from swa_cli_helpers import run as _run


@pytest.fixture
def inputs(tmp_path):
    labels = np.ones((12, 12), dtype=np.uint8)
    labels[:, 6:] = 2
    np.save(tmp_path / "labels.npy", labels)
    (tmp_path / "sig.csv").write_text(
        "label,name,tiles,mean_mean,mean_std,variance_mean,variance_std\n"
        "1,grey,20,40.0,5.0,1.0,0.1\n2,white,20,80.0,2.0,1.0,0.1\n")
    return tmp_path, labels


def test_the_command_gives_the_library_result_and_writes_table_and_histogram(inputs, capsys):
    tmp, labels = inputs
    table, figure = tmp / "samples.csv", tmp / "hist.png"
    rc, out, err = _run(capsys, "simulate", tmp / "labels.npy", "--stochastic", tmp / "sig.csv",
                        "--samples", 5, "--map", "log-linear:-2,0.05", "--tile-size", 4,
                        "--random-seed", 9, "--spacing", 0.5, 0.5, "--sample-table", table,
                        "--histogram", figure, "--json")
    assert rc == 0, err
    report = json.loads(out)["stochastic"]
    rows = [{"label": 1, "name": "grey", "tiles": 20, "mean_mean": 40.0, "mean_std": 5.0},
            {"label": 2, "name": "white", "tiles": 20, "mean_mean": 80.0, "mean_std": 2.0}]
    ref = stochastic_k_eff(labels, rows, samples=5, correlation=2.0, spacing=0.5,
                           property_map="log-linear:-2,0.05", seed=9)
    for axis in ("x", "y"):
        assert report["k_eff"][axis]["mean"] == pytest.approx(ref.statistics(axis)["mean"],
                                                              rel=1e-12)
        assert report["k_eff"][axis]["sem"] > 0
    assert report["materials"]["1"]["log_k_mean"] == pytest.approx(-2 + 0.05 * 40)
    assert report["materials"]["2"]["log_k_std"] == pytest.approx(0.05 * 2.0)
    lines = table.read_text().splitlines()
    assert lines[0] == "sample,k_eff_x,k_eff_y" and len(lines) == 6
    assert float(lines[1].split(",")[1]) == ref.samples["x"][0]
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_text_output_names_mean_interval_and_error(inputs, capsys):
    tmp, _ = inputs
    rc, out, err = _run(capsys, "simulate", tmp / "labels.npy", "--stochastic", tmp / "sig.csv",
                        "--samples", 3, "--map", "log-linear:-2,0.05", "--tile-size", 4,
                        "--axes", "x", "-k", "white=2.5")
    assert rc == 0, err
    assert "Monte-Carlo standard error" in out and "95 % of samples in" in out
    assert "material 1 (grey)" in out and "material 2" not in out    # white stays fixed


@pytest.mark.parametrize(("extra", "match"), [
    ([], "needs --map log-linear:A,B"),
    (["--map", "log-linear:0,1"], "needs --tile-size T"),
    (["--map", "exp:0,1", "--tile-size", "4"], "must be log-linear:a,b"),
    (["--map", "log-linear:0,1", "--tile-size", "4", "--samples", "1"], "--samples must be 2"),
    (["--map", "log-linear:0,1", "--tile-size", "4", "--transient", "1"],
     "does not combine with --transient"),
    (["--map", "log-linear:0,1", "--tile-size", "4", "-o", "f.vtu"],
     "does not combine with --output"),
    (["--map", "log-linear:0,1", "--tile-size", "4", "--workers", "0"], "--workers must be 1"),
    (["--map", "log-linear:0,1", "--tile-size", "4", "--histogram", "h.txt"],
     "ending in .png, .pdf, .svg"),
])
def test_bad_stochastic_arguments_exit_2_with_one_sentence(inputs, capsys, extra, match):
    import re

    tmp, _ = inputs
    rc, out, err = _run(capsys, "simulate", tmp / "labels.npy", "--stochastic",
                        tmp / "sig.csv", *extra)
    assert rc == 2 and out == ""
    assert re.search(match, err), err


def test_stochastic_options_without_stochastic_and_no_conductivity_are_refused(inputs, capsys):
    tmp, _ = inputs
    rc, _, err = _run(capsys, "simulate", tmp / "labels.npy", "-k", "1=1", "2=2",
                      "--samples", 5)
    assert rc == 2 and "--samples applies to a stochastic run" in err
    rc, _, err = _run(capsys, "simulate", tmp / "labels.npy")
    assert rc == 2 and "needs --conductivity" in err


def test_an_existing_output_is_refused_before_any_work(inputs, capsys):
    tmp, _ = inputs
    (tmp / "samples.csv").write_text("keep")
    rc, _, err = _run(capsys, "simulate", tmp / "labels.npy", "--stochastic", tmp / "sig.csv",
                      "--map", "log-linear:0,0.01", "--tile-size", 4, "--sample-table",
                      tmp / "samples.csv")
    assert rc == 2 and "exists" in err
    assert (tmp / "samples.csv").read_text() == "keep"


def test_the_tile_size_defaults_to_the_signatures_scale(inputs, capsys):
    tmp, _ = inputs
    text = (tmp / "sig.csv").read_text().splitlines()
    (tmp / "scaled.csv").write_text("\n".join([text[0] + ",scale"] + [t + ",2" for t in text[1:]]))
    run = ["simulate", tmp / "labels.npy", "--samples", 3, "--map", "log-linear:-2,0.05",
           "--axes", "x", "--json"]
    rc, out, err = _run(capsys, *run, "--stochastic", tmp / "scaled.csv")
    assert rc == 0, err
    rc, same, err = _run(capsys, *run, "--stochastic", tmp / "sig.csv", "--tile-size", 4)
    assert rc == 0, err
    a, b = json.loads(out)["stochastic"], json.loads(same)["stochastic"]
    assert a["correlation"] == [4.0, 4.0] and a["k_eff"] == b["k_eff"]
    (tmp / "mixed.csv").write_text(
        "\n".join([text[0] + ",scale", text[1] + ",2", text[2] + ",3"]))
    rc, _, err = _run(capsys, *run, "--stochastic", tmp / "mixed.csv")
    assert rc == 2 and "not one whole number" in err
