"""``swa-imesh simulate`` as a user runs it: files in, k_eff and a ParaView file out."""

from __future__ import annotations

import json

import numpy as np
import pytest
from simulate_cases import checkerboard

from napari_swa_imesh.simulate import simulate
from swa_cli_helpers import run as _run


@pytest.fixture
def labels_file(tmp_path):
    from scipy import ndimage

    f = ndimage.gaussian_filter(np.random.default_rng(2).standard_normal((10, 12, 14)), 1.5)
    labels = (np.digitize(f, np.quantile(f, [0.4, 0.7])) + 1).astype(np.uint8)
    path = tmp_path / "labels.npy"
    np.save(path, labels)
    return path, labels


def test_simulate_labels_prints_k_eff_and_writes_a_field_paraview_reads(labels_file, capsys):
    import pyvista

    path, labels = labels_file
    out_path = path.parent / "field.vtu"
    # the interval has its own tests: here the command must equal the library and write
    rc, out, err = _run(capsys, "simulate", path, "-k", "1=1", "2=10", "3=0.1", "--spacing",
                        "2", "1", "1", "--no-interval", "-o", out_path, "--json")
    assert rc == 0, err
    report = json.loads(out)
    expected = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1}, spacing=(2, 1, 1), interval=False)
    assert report["k_eff"] == pytest.approx(expected.k_eff, rel=1e-9)
    assert set(report) >= {"k_eff", "bounds", "dofs", "residual", "iterations", "seconds"}
    grid = pyvista.read(out_path)
    assert grid.n_cells == expected.mesh.n_cells
    assert np.allclose(np.asarray(grid.point_data["potential_x"]), expected.potential["x"])
    assert grid.cell_data["flux_z"].shape == (grid.n_cells, 3)
    assert set(np.unique(grid.cell_data["material"])) == {1, 2, 3}
    # x in the file is the column axis: the potential rises along it from 0 to 1
    x = grid.points[:, 0]
    u = np.asarray(grid.point_data["potential_x"])
    assert np.allclose(u[x == x.min()], 0) and np.allclose(u[x == x.max()], 1)


def test_simulate_a_mesh_file_gives_the_labels_result(labels_file, capsys, tmp_path):
    path, labels = labels_file
    mesh_path = tmp_path / "mesh.vtu"
    assert _run(capsys, "mesh", path, "-o", mesh_path)[0] == 0
    rc, out, err = _run(capsys, "simulate", mesh_path, "-k", "1=1", "2=10", "3=0.1",
                        "--axes", "y", "--json")
    assert rc == 0, err
    # a mesh file cannot be adapted (no labels): the default is P2 on it as it is
    expected = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1}, axes="y", adapt=0).k_eff["y"]
    assert json.loads(out)["k_eff"]["y"] == pytest.approx(expected, rel=1e-9)
    rc, out, err = _run(capsys, "simulate", path, "-k", "1=1", "2=10", "3=0.1",
                        "--order", "2", "--axes", "y")
    assert rc == 0 and "P2" in out and "k_eff y" in out


@pytest.mark.parametrize("args, message", [
    (["-k", "1=1", "2=10"], "material 3 has no conductivity"),
    (["-k", "1=1", "2=0", "3=1"], "must be positive"),
    (["-k", "1=1", "2=nan", "3=1"], "not finite"),
    (["-k", "1=1", "2=1", "3=1", "steel=2"], "not in the mesh"),
    (["-k", "1=1", "2=1", "3=1", "--order", "3"], "--order must be auto, 1 or 2"),
    (["-k", "1=1", "2=1", "3=1", "--adapt", "3"], "--adapt must be auto, 0, 1 or 2"),
    (["-k", "1=1", "2=1", "3=1", "-o", "field.png"], "use .vtu or .xdmf"),
    (["-k", "1=1", "2=1", "3=1", "-o", "existing.vtu"], "--force"),
    (["-k", "1=", "2=1"], "MATERIAL=VALUE"),
    (["-k", "1=1", "2=1", "3=1", "--spacing", "1", "-2", "1"], "spacing"),
    (["-k", "1=1", "2=1", "3=1", "--max-aspect", "0.5"], "--max-aspect must be a finite"),
    (["-k", "1=1", "2=1", "3=1", "--max-aspect", "1.3", "--transient", "1"],
     "--max-aspect is for the steady k_eff run"),
])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(labels_file, capsys, args,
                                                           message):
    path, _ = labels_file
    folder = path.parent
    (folder / "existing.vtu").write_text("keep")
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    argv = ["simulate", path, *[a if not a.endswith((".png", ".vtu")) else folder / a
                                for a in args]]
    rc, out, err = _run(capsys, *argv)
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("swa-imesh simulate: error:")
    import re

    assert re.search(message, err), err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_a_mesh_input_refuses_label_options(labels_file, capsys, tmp_path):
    path, _ = labels_file
    mesh_path = tmp_path / "m.vtu"
    assert _run(capsys, "mesh", path, "-o", mesh_path)[0] == 0
    rc, _, err = _run(capsys, "simulate", mesh_path, "-k", "1=1", "2=1", "3=1",
                      "--spacing", "2")
    assert rc == 2 and "label image" in err
    rc, _, err = _run(capsys, "simulate", mesh_path, "-k", "1=1", "2=1", "3=1",
                      "--max-aspect", "1.3")
    assert rc == 2 and "label image" in err


def test_a_floating_region_exits_2(tmp_path, capsys):
    labels = np.full((8, 8, 8), 2, dtype=np.uint8)
    labels[2:6, 2:6, 2:6] = 1
    labels[3:5, 3:5, 3:5] = 3                   # 3 floats inside the excluded 1
    np.save(tmp_path / "island.npy", labels)
    rc, _, err = _run(capsys, "simulate", tmp_path / "island.npy", "-k", "2=1", "3=5",
                      "--exclude", "1", "-o", tmp_path / "f.vtu")
    assert rc == 2 and "material 3" in err and "not connected to the x faces" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["island.npy"]


def test_transient_run_writes_a_series_that_meshio_and_vtk_read(labels_file, capsys):
    import meshio
    import pyvista

    path, labels = labels_file
    out = path.parent / "series.xdmf"
    rc, stdout, err = _run(capsys, "simulate", path, "-k", "1=1", "2=10", "3=0.1",
                           "--transient", "5", "--steps", "6", "--save-every", "2",
                           "--fixed", "xmin=1", "--capacity", "2=3", "-o", out, "--json")
    assert rc == 0, err
    report = json.loads(stdout)
    assert report["times"] == pytest.approx([0, 5 / 3, 10 / 3, 5])
    assert sorted(p.name for p in path.parent.iterdir()) == ["labels.npy", "series.h5",
                                                            "series.xdmf"]
    with meshio.xdmf.TimeSeriesReader(out) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == 4
        t, point_data, cell_data = reader.read_data(3)
    assert t == pytest.approx(5.0)
    u = point_data["u"]
    assert np.allclose(u[points[:, 0] == points[:, 0].min()], 1.0)   # the fixed face
    assert set(np.unique(cell_data["material"][0])) == {1, 2, 3}
    vtk = pyvista.get_reader(str(out))
    assert vtk.number_time_points == 4
    vtk.set_active_time_point(3)
    grid = vtk.read()
    assert grid.n_points == len(points) and np.allclose(grid.point_data["u"], u)


@pytest.mark.parametrize("args, message", [
    (["--fixed", "xmin=1"], "add --transient"),
    (["--transient", "1", "-o", "s.vtu"], "XDMF/HDF5"),
    (["--transient", "1", "--fixed", "xmin"], "FACE=VALUE"),
    (["--transient", "1", "--fixed", "wmin=1"], "unknown face 'wmin'"),
    (["--transient", "1", "--capacity", "bone=2"], "capacity names material 'bone'"),
    (["--transient", "1", "--capacity", "2=x"], "MATERIAL=VALUE"),
    (["--transient", "1", "--fixed", "xmin=1", "xmin=2"], "face xmin twice"),
    (["--transient", "0"], "duration must be a positive"),
    (["--transient", "1", "--axes", "x"], "--axes"),
])
def test_bad_transient_input_exits_2(labels_file, capsys, args, message):
    path, _ = labels_file
    argv = ["simulate", path, "-k", "1=1", "2=1", "3=1",
            *[a if not a.endswith(".vtu") else path.parent / a for a in args]]
    rc, _, err = _run(capsys, *argv)
    assert rc == 2 and message in err and err.count("\n") == 1
    assert sorted(p.name for p in path.parent.iterdir()) == ["labels.npy"]


def test_a_mesh_file_without_materials_is_refused(tmp_path, capsys):
    import meshio

    points = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=float)
    meshio.write(tmp_path / "plain.vtu", meshio.Mesh(points, [("triangle", [[0, 1, 2],
                                                                            [1, 3, 2]])]))
    rc, _, err = _run(capsys, "simulate", tmp_path / "plain.vtu", "-k", "0=1",
                      "-o", tmp_path / "f.vtu")
    assert rc == 2 and "has no material per element" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.vtu"]


def test_a_mesh_file_with_voids_warns_that_its_box_is_its_extent(labels_file, capsys):
    path, labels = labels_file
    mesh_path = path.parent / "holes.vtu"
    assert _run(capsys, "mesh", path, "-o", mesh_path, "--exclude", "3")[0] == 0
    rc, out, err = _run(capsys, "simulate", mesh_path, "-k", "1=1", "2=2", "--axes", "y")
    assert rc == 0 and "warning: the mesh has voids" in err


@pytest.mark.parametrize("flag", [["--steps", "5"], ["--save-every", "2"]])
def test_transient_step_options_need_transient(labels_file, capsys, flag):
    path, _ = labels_file
    rc, _, err = _run(capsys, "simulate", path, "-k", "1=1", "2=1", "3=1", *flag)
    assert rc == 2 and "add --transient" in err


def test_a_grey_image_given_as_labels_is_named_as_such(tmp_path, capsys):
    image = np.random.default_rng(0).integers(0, 200, (16, 16)).astype(np.uint8)
    np.save(tmp_path / "grey.npy", image)
    rc, _, err = _run(capsys, "simulate", tmp_path / "grey.npy", "-k", "1=1")
    assert rc == 2 and "is it an image rather than a label image?" in err


def test_the_interval_and_the_memory_budget_on_the_command_line(tmp_path, capsys):
    """Issue 26: k_eff as a certified interval, a wide one said, a budget in bytes."""
    layers = np.ones((6, 9), dtype=np.uint8)
    layers[:, 3:] = 2
    np.save(tmp_path / "layers.npy", layers)
    rc, out, err = _run(capsys, "simulate", tmp_path / "layers.npy", "-k", "1=1", "2=4",
                        "--json")
    assert rc == 0, err
    report = json.loads(out)
    exact = 1 / (1 / 3 + (2 / 3) / 4)
    assert report["interval"]["x"]["lower"] == pytest.approx(exact, rel=1e-10)
    assert report["interval"]["x"]["upper"] == pytest.approx(exact, rel=1e-10)
    assert report["interval"]["x"]["gap"] < 1e-10 and report["warnings"] == []
    assert 0 < report["memory_estimate_bytes"] <= report["memory_budget_bytes"]
    rc, out, _ = _run(capsys, "simulate", tmp_path / "layers.npy", "-k", "1=1", "2=4",
                      "--json", "--no-interval")
    assert rc == 0 and "interval" not in json.loads(out)
    # a checkerboard on a coarse mesh kept as asked: the wide interval is said
    np.save(tmp_path / "board.npy", checkerboard(2, 4))
    rc, out, _ = _run(capsys, "simulate", tmp_path / "board.npy", "-k", "1=1", "2=10",
                      "--axes", "x", "--order", "1", "--adapt", "0")
    assert rc == 0
    assert "certified x:" in out and "warning: the interval along x is" in out
    # the budget is checked before any solve, with the estimate in the sentence
    rc, _, err = _run(capsys, "simulate", tmp_path / "board.npy", "-k", "1=1", "2=10",
                      "--order", "2", "--memory", "1k")
    assert rc == 2 and "above the memory budget of 1 kB" in err
    rc, _, err = _run(capsys, "simulate", tmp_path / "board.npy", "-k", "1=1", "2=10",
                      "--memory", "lots")
    assert rc == 2 and "--memory takes a size" in err
