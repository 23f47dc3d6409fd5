"""``swa-imesh simulate --model fisher-kpp|drug``: the series meshio reads back, the table,
the plot, and exit 2 with one sentence for what the door refuses."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from swa_cli_helpers import run as _run


@pytest.fixture
def brain(tmp_path):
    # 1: CSF (D = 0, not meshed), 2: white matter, 3: grey matter
    labels = np.full((12, 16), 3, dtype=np.uint8)
    labels[:6] = 2
    labels[:, :2] = 1
    path = tmp_path / "brain.npy"
    np.save(path, labels)
    return path


def test_fisher_kpp_writes_a_series_meshio_reads_a_table_and_a_plot(brain, capsys):
    import meshio

    out = brain.parent / "growth.xdmf"
    rc, text, err = _run(capsys, "simulate", brain, "--model", "fisher-kpp", "-D", "2=1",
                         "3=0.2", "--rate", "1", "--seed", "6,6:2", "--duration", "3",
                         "--steps", "3", "--front-cells", "1", "-o", out, "--json")
    assert rc == 0, err
    report = json.loads(text)
    assert report["model"] == "fisher-kpp" and report["times"] == [0, 1, 2, 3]
    assert report["balance_residual"] < 1e-9
    assert report["volume"][-1] > report["volume"][0]
    with meshio.xdmf.TimeSeriesReader(out) as reader:
        points, cells = reader.read_points_cells()
        times, fields = [], []
        for k in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(k)
            times.append(t)
            fields.append(point_data["c"])
    assert times == [0.0, 1.0, 2.0, 3.0]
    assert len(points) == len(fields[0])
    assert np.all((np.stack(fields) >= 0) & (np.stack(fields) <= 1))
    assert set(np.unique(cell_data["material"][0])) == {2, 3}        # CSF not meshed
    assert points[:, 0].min() == pytest.approx(2.0)                  # x = column
    with open(out.with_suffix(".csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["time"]) for r in rows] == [0.0, 1.0, 2.0, 3.0]
    assert float(rows[-1]["volume"]) == pytest.approx(report["volume"][-1])
    assert float(rows[-1]["volume_2"]) > float(rows[-1]["volume_3"])  # faster in white
    assert float(rows[-1]["front_2"]) > float(rows[0]["front_2"])
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_drug_from_a_fixed_face(brain, capsys):
    rc, text, err = _run(capsys, "simulate", brain, "--model", "drug", "-D", "2=1", "3=1",
                         "--decay", "1", "--fixed", "xmax=1", "--duration", "5",
                         "--steps", "1", "--front-cells", "1", "--json")
    assert rc == 0, err
    report = json.loads(text)
    assert report["balance"]["boundary"][-1] > 0 > report["balance"]["decay"][-1]
    assert report["balance_residual"] < 1e-9


@pytest.mark.parametrize("args, message", [
    (["--model", "fisher-kpp", "--rate", "1", "--seed", "6,6:2", "--duration", "1"],
     "needs -D"),
    (["--model", "fisher-kpp", "-D", "2=1", "--seed", "6,6:2", "--duration", "1"],
     "positive --rate"),
    (["--model", "fisher-kpp", "-D", "2=1", "--rate", "1", "--duration", "1"], "--seed"),
    (["--model", "fisher-kpp", "-D", "2=1", "--rate", "1", "--seed", "6,6", "--duration",
      "1"], "X,Y"),
    (["--model", "fisher-kpp", "-D", "2=1", "--rate", "1", "--seed", "6,6:2"],
     "--duration"),
    (["--model", "fisher-kpp", "-D", "2=1", "--rate", "1", "--seed", "6,6:2", "--duration",
      "1", "-k", "2=1"], "--conductivity is for the conductivity model"),
    (["--model", "fisher-kpp", "-D", "2=1", "--rate", "1", "--seed", "6,6:2", "--duration",
      "1", "--kill", "3:1:1"], "--kill needs"),
    (["--model", "fisher-kpp", "-D", "2=1", "--rate", "1", "--seed", "6,6:2", "--duration",
      "1", "-o", "out.vtu"], "XDMF"),
    (["--model", "drug", "-D", "2=1", "--duration", "1"], "needs a source"),
    (["--model", "drug", "-D", "2=1", "--duration", "1", "--fixed", "xmax=1", "--rate",
      "1"], "--decay"),
    ([], "needs --conductivity"),
])
def test_bad_growth_input_exits_2_with_one_sentence(brain, capsys, args, message):
    rc, out, err = _run(capsys, "simulate", brain, *args)
    assert rc == 2
    assert message in err and err.count("\n") == 1
    assert list(brain.parent.iterdir()) == [brain]


def test_json_run_says_each_warning_once(brain, capsys, monkeypatch):
    import warnings

    from napari_swa_imesh.simulate import _growth

    real = _growth.simulate_growth

    def warning_growth(*args, **kwargs):
        result = real(*args, **kwargs)
        result.warnings.append("a note the run made")
        warnings.warn("a note the run made", UserWarning, stacklevel=2)
        return result

    monkeypatch.setattr(_growth, "simulate_growth", warning_growth)
    rc, text, err = _run(capsys, "simulate", brain, "--model", "fisher-kpp", "-D", "2=1",
                         "--rate", "1", "--seed", "6,6:2", "--duration", "1", "--steps", "1",
                         "--front-cells", "1", "--json")
    assert rc == 0, err
    assert err.count("a note the run made") == 1
    assert json.loads(text)["warnings"] == ["a note the run made"]
