"""``swa-imesh mesh --refine/--max-size/--coarsen/--no-subdivide`` and ``bounds --spacing``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from napari_swa_imesh.mesh.formats._export import read_mesh
from napari_swa_imesh.mesh.model._quality import signed_volumes
from swa_cli_helpers import run


def blob() -> np.ndarray:
    lab = np.zeros((10, 12, 9), np.uint8)
    lab[2:8, 3:10, 2:7] = 1
    lab[4:6, 5:7, 3:5] = 2
    return lab


def snapshot(folder) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_anisotropic_spacing_is_subdivided_and_reported(tmp_path, capsys):
    np.save(tmp_path / "lab.npy", blob())
    code, out, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "m.vtu",
                       "--spacing", "2.5", "1", "1", "--json")
    assert code == 0
    report = json.loads(out)
    # the default limit 1.25 takes 2.5 / 2 cells; its bound is 1.3754 and 29.50 deg
    assert report["lattice"]["factors"] == [2, 1, 1]
    assert report["lattice"]["max_aspect"] == 1.25
    assert report["worst_ratio"] <= 1.37536
    assert 29.49 <= report["min_dihedral"] and report["max_dihedral"] <= 135
    assert report["checks"]["all_passed"]
    mesh = read_mesh(tmp_path / "m.vtu")
    vol = signed_volumes(mesh.points, mesh.cells)
    for m in (0, 1, 2):
        assert vol[mesh.material == m].sum() == pytest.approx((blob() == m).sum() * 2.5)
    code, out, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "s.vtu",
                       "--spacing", "2.5", "1", "1", "--no-subdivide", "--json")
    assert json.loads(out)["worst_ratio"] > 2                  # stretched: no bound


def test_refine_max_size_and_coarsen_in_the_text_summary(tmp_path, capsys):
    np.save(tmp_path / "lab.npy", blob())
    code, out, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "r.vtu",
                       "--refine", "1", "--max-size", "4")
    assert code == 0
    assert "2 x 2 x 2 cells per voxel (refine 1" in out
    code, out, err = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "c.vtu",
                         "--coarsen", "1")
    assert code == 0
    assert "coarsened to 2^1 voxel blocks" in out and "volume change per material" in out


def test_coarsen_that_removes_a_material_warns_naming_it(tmp_path, capsys):
    lab = blob()
    lab[0, 0, 0] = 3
    np.save(tmp_path / "lab.npy", lab)
    code, out, err = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "c.vtu",
                         "--coarsen", "1", "--material-names", "3=speck", "--json")
    assert code == 0
    # the 2x2x2 material 2 sits off the block grid and goes too
    assert "removed material(s) 2, 3 (speck) entirely" in err
    assert json.loads(out)["coarsen"]["lost"] == [2, 3]


@pytest.mark.parametrize("extra, message", [
    (["--refine", "-1"], "refine must be a whole number from 0 to 4"),
    (["--refine", "5"], "refine must be a whole number from 0 to 4"),
    (["--max-size", "0.5"], "below the longest edge of the smallest element"),
    (["--max-size", "-2"], "--max-size must be a positive length"),
    (["--coarsen", "6"], "coarsen must be a whole number from 0 to 5"),
    (["--method", "delaunay", "--refine", "1"], "the delaunay method meshes voxels"),
    (["--method", "delaunay", "--periodic"], "periodic meshes need the template method"),
    (["--spacing", "100", "1", "1"], "resample the image closer to cubic voxels"),
    (["--max-aspect", "0.9"], "--max-aspect must be a finite number >= 1"),
    (["--max-aspect", "nan"], "--max-aspect must be a finite number >= 1"),
    (["--max-aspect", "1.3", "--no-subdivide"], "give one or the other"),
])
def test_bad_resolution_options_exit_2_and_leave_the_folder_unchanged(tmp_path, capsys,
                                                                      extra, message):
    np.save(tmp_path / "lab.npy", blob())
    (tmp_path / "m.vtu").write_bytes(b"keep me")
    before = snapshot(tmp_path)
    code, _, err = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "m.vtu",
                       "--force", *extra)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert snapshot(tmp_path) == before


def test_bounds_prints_the_bound_per_residual_aspect_and_for_a_spacing(capsys):
    code, out, _ = run(capsys, "bounds", "--dim", "3", "--spacing", "2.5", "1", "1")
    assert code == 0
    assert "residual aspect" in out and "  1.20    1.3185" in out
    assert "chosen (--max-aspect 1.25): 2 x 1 x 1 cells per voxel" in out
    code, out, _ = run(capsys, "bounds", "--dim", "3", "--json")
    rows = json.loads(out)["by_residual_aspect"]
    assert rows[0]["aspect"] == 1.0 and rows[0]["worst_ratio"] == pytest.approx(np.sqrt(5) / 2)
    assert all(a["worst_ratio"] <= b["worst_ratio"] for a, b in zip(rows, rows[1:]))


def test_max_aspect_trades_cells_for_the_bound(tmp_path, capsys):
    np.save(tmp_path / "lab.npy", blob())
    reports = {}
    for limit in ("1.2", "1.25", "1.5"):
        code, out, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "m.vtu",
                           "--force", "--spacing", "2.5", "1", "1", "--max-aspect", limit,
                           "--json")
        assert code == 0
        reports[limit] = json.loads(out)
    # 2.5 / 3 -> 1.2, 2.5 / 2 -> 1.25, 2.5 / 2 too at 1.5 (2.5 / 1 is beyond it)
    assert [reports[k]["lattice"]["factors"][0] for k in ("1.2", "1.25", "1.5")] == [3, 2, 2]
    for limit, r in reports.items():
        assert r["lattice"]["max_aspect"] == float(limit)
        assert r["worst_ratio"] <= r["lattice"]["bounds"]["worst_ratio"] + 1e-9
        assert r["checks"]["all_passed"]
    assert reports["1.2"]["elements"] > reports["1.25"]["elements"]


def test_bounds_lists_every_choice_for_a_spacing_and_marks_the_chosen(capsys):
    code, out, _ = run(capsys, "bounds", "--dim", "3", "--spacing", "0.9375", "0.9375", "1.5",
                       "--json")
    assert code == 0
    report = json.loads(out)
    choices = report["choices"]
    assert [c["factors"] for c in choices[:3]] == [[1, 1, 1], [1, 1, 2], [2, 2, 3]]
    assert [c["cells_per_voxel"] for c in choices[:3]] == [1, 2, 12]
    assert choices[1]["residual_aspect"] == pytest.approx(1.25)
    assert choices[1]["bounds"]["worst_ratio"] <= 1.40
    assert report["lattice"]["factors"] == [1, 1, 2]
    code, out, _ = run(capsys, "bounds", "--dim", "3", "--spacing", "0.9375", "0.9375", "1.5",
                       "--max-aspect", "1.2")
    assert code == 0
    chosen = [line for line in out.splitlines() if line.endswith("<- chosen")]
    assert len(chosen) == 1 and "2 x 2 x 3 = 12" in chosen[0]
    code, _, err = run(capsys, "bounds", "--dim", "3", "--max-aspect", "1.2")
    assert code == 2 and "give --spacing" in err
