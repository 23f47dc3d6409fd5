"""The growth table's CSV read back: a material's columns are named by its name where it
has one, by its label where it has none (or where names would give one column twice), and
hold the same numbers as :func:`growth_table`'s columns by label."""

from __future__ import annotations

import csv

import numpy as np

from napari_swa_imesh.cli import main
from napari_swa_imesh.simulate import growth_table, simulate_growth, write_growth
from napari_swa_imesh.simulate._growth_output import _csv_columns


def _labels():
    labels = np.full((8, 12), 3, dtype=np.uint8)     # 1: white, 2: grey, 3: unnamed
    labels[:3] = 1
    labels[3:5] = 2
    return labels


def _read(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_the_csv_names_a_material_s_columns_by_its_name(tmp_path):
    result = simulate_growth(_labels(), {1: 1.0, 2: 0.5, 3: 0.2}, rate=1.0,
                             seed=((2.0, 2.0), 2.0), duration=2.0, saves=2, front_cells=1.0,
                             material_names={1: "white matter", 2: "grey, cortical"})
    write_growth(result, tmp_path / "g.xdmf")
    rows = _read(tmp_path / "g.csv")
    table = growth_table(result)
    assert list(rows[0]) == [{"volume_1": "volume_white matter",
                              "front_1": "front_white matter",
                              "volume_2": "volume_grey, cortical",
                              "front_2": "front_grey, cortical"}.get(k, k) for k in table]
    for label, name in ((1, "white matter"), (2, "grey, cortical"), (3, "3")):
        for prefix in ("volume", "front"):
            got = np.array([float(r[f"{prefix}_{name}"] or "nan") for r in rows])
            assert np.allclose(got, table[f"{prefix}_{label}"], rtol=1e-9, equal_nan=True)
    assert np.any(table["volume_1"] > 0) and np.all(table["volume_2"] >= 0)


def test_names_that_would_give_one_column_twice_keep_the_label():
    assert _csv_columns([1, 2, 3], {1: "x", 2: "x"}) == {
        "volume_1": "volume_x (1)", "front_1": "front_x (1)",
        "volume_2": "volume_x (2)", "front_2": "front_x (2)",
        "volume_3": "volume_3", "front_3": "front_3"}
    # a name that spells another material's label: that material keeps its label
    assert _csv_columns([2, 3], {3: "2"})["volume_3"] == "volume_2 (3)"
    assert _csv_columns([2, 3], {3: "2"})["volume_2"] == "volume_2"
    # a name that spells a fallback: every material by its label
    assert set(_csv_columns([3, 4, 5], {3: "x", 4: "x (3)", 5: "x"}).values()) == {
        f"{p}_{m}" for m in (3, 4, 5) for p in ("volume", "front")}


def test_the_command_line_names_the_columns_by_material_names(tmp_path, capsys):
    labels = _labels()
    np.save(tmp_path / "t.npy", labels)
    out = tmp_path / "growth.xdmf"
    rc = main([str(a) for a in ("simulate", tmp_path / "t.npy", "--model", "fisher-kpp",
                                "-D", "1=1", "2=0.5", "3=0.2", "--rate", "1",
                                "--seed", "2,2:2", "--duration", "2", "--steps", "2",
                                "--front-cells", "1",
                                "--material-names", "1=white matter", "-o", out)])
    assert rc == 0, capsys.readouterr().err
    header = list(_read(out.with_suffix(".csv"))[0])
    assert {"volume_white matter", "front_white matter", "volume_2", "volume_3"} <= set(header)
    assert "volume_1" not in header
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
