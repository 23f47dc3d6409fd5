"""The signatures + k_eff report: rows matched by label (or name), never shifted; files."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.io import read_image
from napari_swa_imesh.simulate import (
    read_signatures,
    simulate,
    simulation_report,
    write_report,
)
from swa_cli_helpers import run as _run


def _csv_blocks(path):
    """The report CSV's two blocks, read by the csv module: (materials, k_eff rows)."""
    with open(path, newline="") as f:
        lines = list(csv.reader(f))
    blank = lines.index([])
    header, *rows = lines[:blank]
    return [dict(zip(header, r)) for r in rows], lines[blank + 1:]


@pytest.fixture(scope="module")
def segmented(tmp_path_factory):
    """A real ``swa-imesh segment --signatures`` run on the generated brick/grass mosaic."""
    from napari_swa_imesh.data import texture_mosaic
    from napari_swa_imesh.segmentation import Samples, save_samples

    folder = tmp_path_factory.mktemp("segmented")
    image, _ = texture_mosaic(("brick", "grass"), size=64)
    np.save(folder / "mosaic.npy", image)
    save_samples(Samples.from_dict({
        "materials": [{"label": 1, "name": "brick"}, {"label": 2, "name": "grass"}],
        "boxes": [{"label": 1, "start": [0, 0], "stop": [64, 28]},
                  {"label": 2, "start": [0, 36], "stop": [64, 64]}]}), folder / "s.json")
    assert main(["segment", str(folder / "mosaic.npy"), "--samples", str(folder / "s.json"),
                 "--signatures", str(folder / "sig.csv"), "-o",
                 str(folder / "labels.tif")]) == 0
    labels, _ = read_image(folder / "labels.tif")
    return folder, labels


def test_segment_signatures_round_trip_into_the_simulate_report(segmented, capsys, tmp_path):
    folder, labels = segmented
    sig = folder / "sig.csv"
    with open(sig, newline="") as f:
        written = list(csv.DictReader(f))
    assert [r["name"] for r in written] == ["brick", "grass"]
    # the names come from the signatures, so -k can use them
    rc, out, err = _run(capsys, "simulate", folder / "labels.tif", "-k", "brick=1",
                        "grass=10", "--signatures", sig, "--report", tmp_path / "r.csv",
                        "--json")
    assert rc == 0, err
    assert "warning" not in err
    report = json.loads(out)
    expected = simulate(labels, {1: 1.0, 2: 10.0})
    assert report["k_eff"] == pytest.approx(expected.k_eff, rel=1e-12)
    assert str(tmp_path / "r.csv") in report["output"]
    materials, effective = _csv_blocks(tmp_path / "r.csv")
    for row, json_row, sig_row in zip(materials, report["materials"], written):
        label = int(sig_row["label"])
        assert int(row["label"]) == json_row["label"] == label
        assert row["name"] == json_row["name"] == sig_row["name"]
        fraction = np.mean(labels == label)           # pixels of the label / box area
        assert float(row["volume_fraction"]) == pytest.approx(fraction, rel=1e-12)
        assert json_row["volume_fraction"] == pytest.approx(fraction, rel=1e-12)
        assert float(row["conductivity"]) == json_row["conductivity"] == [1, 10][label - 1]
        for key, value in sig_row.items():
            if key not in ("label", "name"):
                assert float(row[key]) == pytest.approx(float(value), rel=1e-14), key
                assert json_row[key] == pytest.approx(float(value), rel=1e-15), key
    assert effective[0] == ["quantity", "x", "y"]
    k_row = dict(zip(effective[0], effective[1]))
    assert k_row["quantity"] == "k_eff"
    assert float(k_row["x"]) == pytest.approx(expected.k_eff["x"], rel=1e-14)
    lo, hi = expected.bounds["y"]
    assert [r[0] for r in effective[2:]] == ["reuss", "voigt", "lower", "upper", "gap"]
    assert float(effective[2][2]) == pytest.approx(lo) and float(effective[3][2]) == \
        pytest.approx(hi)
    # the certified interval: k_eff is its upper end, the dual bound its lower
    lower, upper = expected.interval["x"]
    assert float(effective[4][1]) == pytest.approx(lower, rel=1e-14)
    assert float(effective[5][1]) == pytest.approx(upper, rel=1e-14) == expected.k_eff["x"]
    assert float(effective[6][1]) == pytest.approx((upper - lower) / lower, rel=1e-9)
    # the report's material block is itself a signatures table
    back = read_signatures(tmp_path / "r.csv")
    assert [r["label"] for r in back] == [1, 2] and back[1]["tiles"] == int(written[1]["tiles"])

    # text mode prints the table; JSON and Markdown files hold the same rows
    rc, out, err = _run(capsys, "simulate", folder / "labels.tif", "-k", "1=1", "2=10",
                        "--signatures", sig, "--report", tmp_path / "r.json")
    assert rc == 0, err
    assert "volume_fraction" in out and "brick" in out and "k_eff x" in out
    saved = json.loads((tmp_path / "r.json").read_text())
    assert saved["materials"] == report["materials"]
    assert saved["k_eff"] == pytest.approx(expected.k_eff, rel=1e-12)
    assert _run(capsys, "simulate", folder / "labels.tif", "-k", "1=1", "2=10",
                "--signatures", sig, "--report", tmp_path / "r.md")[0] == 0
    md = (tmp_path / "r.md").read_text()
    assert f"| 1 | brick | {np.mean(labels == 1):.6g} | 1 | {written[0]['tiles']} |" in md
    assert f"| k_eff | {expected.k_eff['x']:.6g} | {expected.k_eff['y']:.6g} |" in md


def test_materials_on_one_side_only_get_empty_cells_and_a_warning(capsys, tmp_path):
    labels = np.ones((6, 8), dtype=np.uint8)
    labels[:, 4:] = 2
    labels[2:4, 1:3] = 3            # a void inside material 1
    sig = tmp_path / "sig.csv"
    # material 2 has no signature; 4 is not in the labels; 3 is excluded from the mesh
    sig.write_text("label,name,tiles,mean_mean\n1,a,4,0.25\n3,c,2,0.5\n4,d,1,0.75\n")
    result = simulate(labels, {1: 1.0, 2: 2.0}, exclude=[3])
    with pytest.warns(UserWarning) as caught:
        report = simulation_report(result, {1: 1.0, 2: 2.0}, read_signatures(sig))
    assert [str(w.message).split(" has ")[0].split(" is ")[0] for w in caught] == \
        ["material 2", "material 3 (c)", "material 4 (d)"]
    assert "is in the mesh but has no signature" in str(caught[0].message)
    rows = {r["label"]: r for r in report.materials}
    assert list(rows) == [1, 2, 3, 4]
    assert rows[1]["mean_mean"] == 0.25 and rows[1]["volume_fraction"] == pytest.approx(20 / 48)
    assert np.isnan(rows[2]["mean_mean"]) and rows[2]["name"] == ""
    assert rows[2]["volume_fraction"] == pytest.approx(0.5) and rows[2]["conductivity"] == 2
    assert rows[3]["mean_mean"] == 0.5 and rows[3]["conductivity"] is None
    assert np.isnan(rows[3]["volume_fraction"])
    assert rows[4]["name"] == "d" and rows[4]["tiles"] == 1
    assert sum("not in the mesh" in w for w in report.warnings) == 2
    # the command line says the same on stderr, one warning line each
    np.save(tmp_path / "labels.npy", labels)
    rc, out, err = _run(capsys, "simulate", tmp_path / "labels.npy", "-k", "1=1", "2=2",
                        "--exclude", "3", "--signatures", sig, "--json")
    assert rc == 0, err
    assert err.count("swa-imesh simulate: warning: material") == 3
    assert json.loads(out)["materials"][1] == {"label": 2, "name": "", "volume_fraction":
                                               pytest.approx(0.5), "conductivity": 2.0,
                                               "tiles": None, "mean_mean": None}


def test_rows_match_by_name_when_the_table_has_no_labels():
    labels = np.ones((4, 8), dtype=np.uint8)
    labels[:, 4:] = 2
    result = simulate(labels, {"soft": 1.0, "hard": 4.0},
                      material_names={1: "soft", 2: "hard"}, axes="x")
    rows = [{"name": "hard", "tiles": 7}, {"name": "soft", "tiles": 3},
            {"name": "glass", "tiles": 1}]
    with pytest.warns(UserWarning, match="'glass' matches no material"):
        report = simulation_report(result, {1: 1.0, 2: 4.0}, rows)
    assert [(r["label"], r["name"], r["tiles"]) for r in report.materials] == \
        [(1, "soft", 3), (2, "hard", 7), (None, "glass", 1)]
    assert report.k_eff["x"] == pytest.approx(1.6)      # 2 / (1/1 + 1/4)


def test_a_name_that_disagrees_with_the_mesh_is_refused(capsys, tmp_path):
    labels = np.ones((4, 8), dtype=np.uint8)
    labels[:, 4:] = 2
    result = simulate(labels, {1: 1.0, 2: 4.0}, material_names={1: "soft", 2: "hard"})
    with pytest.raises(ValueError, match="name material 2 'soft' but the mesh names it 'hard'"):
        simulation_report(result, {1: 1.0, 2: 4.0}, [{"label": 2, "name": "soft"}])
    np.save(tmp_path / "labels.npy", labels)
    (tmp_path / "sig.csv").write_text("label,name,tiles\n1,hard,3\n2,soft,4\n")
    rc, _, err = _run(capsys, "simulate", tmp_path / "labels.npy", "-k", "1=1", "2=4",
                        "--material-names", "1=soft", "2=hard", "--signatures",
                        tmp_path / "sig.csv", "--report", tmp_path / "r.csv")
    assert rc == 2 and "another labelling" in err and err.count("\n") == 1
    assert not (tmp_path / "r.csv").exists()


def test_periodic_tensor_and_anisotropic_conductivity_in_the_files(tmp_path):
    labels = np.ones((4, 6, 8), dtype=np.uint8)
    labels[:, :, 4:] = 2
    k = {1: [1.0, 2.0, 3.0], 2: 4.0}
    result = simulate(labels, k, protocol="periodic")
    report = simulation_report(result, k)
    assert report.columns == ["label", "name", "volume_fraction", "conductivity"]
    assert report.materials[0]["conductivity"] == [1.0, 2.0, 3.0]
    write_report(report, tmp_path / "r.csv")
    materials, effective = _csv_blocks(tmp_path / "r.csv")
    assert materials[0]["conductivity"] == "1,2,3"
    tensor = np.array([[float(v) for v in row[1:]] for row in effective[4:]])
    assert [row[0] for row in effective[4:]] == ["tensor_x", "tensor_y", "tensor_z"]
    assert np.allclose(tensor, result.tensor, rtol=1e-13)
    assert tensor[0, 0] == pytest.approx(2 / (1 + 1 / 4))     # series along x
    assert tensor[1, 1] == pytest.approx(3.0)                  # parallel: (2 + 4) / 2
    saved = json.loads(write_report(report, tmp_path / "r.json").read_text())
    assert np.allclose(saved["tensor"], result.tensor) and saved["protocol"] == "periodic"
    with pytest.raises(FileExistsError, match="already exists"):
        write_report(report, tmp_path / "r.json")


@pytest.mark.parametrize("text, message", [
    ("material,tiles\n1,3\n", "no 'label' or 'name' column"),
    ("label,name\n", "no material rows"),
    ("label,name,tiles\none,a,3\n", "is not a whole number"),
    ("label,name,tiles\n1,a\n", "2 cells for 3 columns"),
    ("label,name,tiles\n,,3\n", "neither a label nor a name"),
])
def test_a_table_that_is_not_signatures_is_refused(tmp_path, text, message):
    (tmp_path / "sig.csv").write_text(text)
    with pytest.raises(ValueError, match=message):
        read_signatures(tmp_path / "sig.csv")


@pytest.mark.parametrize("args, message", [
    (["--report", "r.txt"], "use .csv, .json, .md"),
    (["--report", "existing.csv"], "--force"),
    (["--signatures", "dup.csv"], "give material 1 twice"),
    (["--signatures", "sig.csv", "--transient", "1"], "do not combine with --transient"),
    (["--report", "r.csv", "--dirichlet", "xmin=0"], "do not combine"),
])
def test_bad_report_options_exit_2_before_any_work(capsys, tmp_path, monkeypatch, args,
                                                   message):
    monkeypatch.chdir(tmp_path)
    np.save("labels.npy", np.ones((4, 4), dtype=np.uint8))
    (tmp_path / "existing.csv").write_text("keep me")
    (tmp_path / "sig.csv").write_text("label,name\n1,a\n")
    (tmp_path / "dup.csv").write_text("label,name\n1,a\n1,b\n")
    rc, out, err = _run(capsys, "simulate", "labels.npy", "-k", "1=1", *args)
    assert rc == 2 and message in err and out == ""
    assert (tmp_path / "existing.csv").read_text() == "keep me"
    assert not (tmp_path / "r.csv").exists()


def test_rounding_in_the_volume_fractions_does_not_void_the_reuss_bound():
    from napari_swa_imesh.simulate._protocols import voigt_reuss

    # a 7M-tetrahedra mesh sums its volumes to about 1e-11 of the box (measured): that is
    # no void, so the harmonic mean stands; a real void (1 %) makes it 0
    tensors = np.stack([np.eye(3), 4 * np.eye(3)])
    voigt, reuss = voigt_reuss(tensors, np.array([0.5, 0.5 - 2e-11]), 0)
    assert reuss == pytest.approx(1 / (0.5 + 0.5 / 4)) and voigt == pytest.approx(2.5)
    assert voigt_reuss(tensors, np.array([0.5, 0.49]), 0)[1] == 0.0
