"""``swa-imesh mesh`` and ``swa-imesh bounds`` end to end, and their refusals of bad input."""

from __future__ import annotations

import importlib.util
import json
import re

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.io import write_labels
from napari_swa_imesh.mesh.formats._export import read_mesh
from swa_cli_helpers import run


def three_materials_2d() -> np.ndarray:
    labels = np.zeros((12, 10), dtype=np.uint8)
    labels[2:9, 3:8] = 1
    labels[5:7, 1:4] = 2
    return labels


def blob_3d() -> np.ndarray:
    rng = np.random.default_rng(3)
    labels = np.ones((6, 5, 7), dtype=np.uint8)
    labels[1:5, 1:4, 2:6] = 2
    labels[rng.random(labels.shape) < 0.05] = 0
    return labels


def one_json(out: str) -> dict:
    lines = out.strip().splitlines()
    assert len(lines) == 1, out
    return json.loads(lines[0])


def test_mesh_2d_json_end_to_end(tmp_path, capsys):
    labels = three_materials_2d()
    np.save(tmp_path / "labels.npy", labels)
    out = tmp_path / "mesh.vtu"
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", out, "--json")
    assert code == 0, stderr
    report = one_json(stdout)
    for key in ("leaves_before_balance", "leaves_after_balance", "vertices", "elements",
                "worst_ratio", "min_angle", "max_angle", "checks", "seconds"):
        assert key in report, key
    assert report["checks"]["all_passed"] is True
    assert report["leaves_after_balance"] >= report["leaves_before_balance"]
    assert set(report["seconds"]) >= {"read", "mesh", "check", "write"}
    assert report["output"] == [str(out), str(tmp_path / "mesh_facets.vtu")]
    mesh = read_mesh(out)
    assert mesh.n_cells == report["elements"]
    assert len(mesh.points) == report["vertices"]
    assert sorted(set(mesh.material.tolist())) == [0, 1, 2]
    # the mesh covers the image box and its quality is what the report says
    np.testing.assert_allclose(mesh.points.max(axis=0), labels.shape)
    assert mesh.quality.max() == pytest.approx(report["worst_ratio"])


def test_mesh_3d_gmsh_with_names_exclude_and_spacing(tmp_path, capsys):
    labels = blob_3d()
    np.save(tmp_path / "vol.npy", labels)
    out = tmp_path / "vol.msh"
    code, stdout, stderr = run(
        capsys, "mesh", tmp_path / "vol.npy", "-o", out, "--exclude", "0",
        "--spacing", "2", "1", "0.5", "--material-names", "1=matrix", "2=inclusion", "--json")
    assert code == 0, stderr
    report = one_json(stdout)
    assert {"min_dihedral", "max_dihedral"} <= set(report)
    assert report["checks"]["all_passed"] is True
    assert report["spacing"] == [2.0, 1.0, 0.5]
    text = out.read_bytes()                   # binary Gmsh; the names are text
    assert b'3 1 "matrix"' in text and b'3 2 "inclusion"' in text
    mesh = read_mesh(out)
    assert 0 not in set(mesh.material.tolist())
    np.testing.assert_allclose(mesh.points.max(axis=0), np.array(labels.shape) * [2, 1, 0.5])
    # volume per material equals the voxel volume of that label
    corners = mesh.points[mesh.cells]
    volumes = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])) / 6
    for material in (1, 2):
        expected = np.count_nonzero(labels == material) * 2 * 1 * 0.5
        assert volumes[mesh.material == material].sum() == pytest.approx(expected)


@pytest.mark.parametrize("suffix", [
    ".inp", ".node",
    pytest.param(".xdmf", marks=pytest.mark.skipif(
        importlib.util.find_spec("h5py") is None, reason="meshio's XDMF needs h5py")),
])
def test_mesh_writes_the_format_the_suffix_names(tmp_path, capsys, suffix):
    np.save(tmp_path / "labels.npy", three_materials_2d())
    code, _, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / f"m{suffix}")
    assert code == 0, stderr
    assert read_mesh(tmp_path / f"m{suffix}").n_cells > 0


def test_mesh_human_summary(tmp_path, capsys):
    np.save(tmp_path / "labels.npy", three_materials_2d())
    code, stdout, _ = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / "m.vtk")
    assert code == 0
    assert "vertices" in stdout and "triangles" in stdout and "checks:" in stdout
    assert "FAILED" not in stdout


def test_spacing_comes_from_the_file_unless_overridden(tmp_path, capsys):
    write_labels(tmp_path / "labels.tif", three_materials_2d(), spacing=(0.5, 0.25))
    code, stdout, _ = run(capsys, "mesh", tmp_path / "labels.tif", "-o", tmp_path / "a.vtu",
                          "--json")
    assert code == 0
    assert one_json(stdout)["spacing"] == pytest.approx([0.5, 0.25])
    code, stdout, _ = run(capsys, "mesh", tmp_path / "labels.tif", "-o", tmp_path / "b.vtu",
                          "--spacing", "3", "--json")
    assert code == 0
    assert one_json(stdout)["spacing"] == [3.0, 3.0]


def test_delaunay_method_runs(tmp_path, capsys):
    np.save(tmp_path / "labels.npy", three_materials_2d())
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / "d.vtu",
                               "--method", "delaunay", "--json")
    assert code in (0, 1), stderr  # 1 would mean written but a check failed
    assert one_json(stdout)["method"] == "delaunay"


def test_failed_checks_exit_1_but_the_mesh_is_written(tmp_path, capsys):
    # Qhull on the corners of a random volume: degenerate and non-conforming (SPEC 2)
    np.save(tmp_path / "vol.npy", np.random.default_rng(0).integers(1, 4, (8, 8, 8)))
    out = tmp_path / "d.vtu"
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "vol.npy", "-o", out,
                               "--method", "delaunay", "--json")
    assert code == 1
    report = one_json(stdout)
    assert report["checks"]["all_passed"] is False and report["checks"]["conforming"] is False
    assert "warning" in stderr and "conforming" in stderr and "--method template" in stderr
    assert out.is_file()


def test_existing_output_needs_force(tmp_path, capsys):
    np.save(tmp_path / "labels.npy", three_materials_2d())
    out = tmp_path / "mesh.vtu"
    out.write_text("precious")
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", out)
    assert code == 2
    assert stderr.startswith("swa-imesh mesh: error:") and "already exists" in stderr
    assert "--force" in stderr
    assert out.read_text() == "precious"
    code, _, _ = run(capsys, "mesh", tmp_path / "labels.npy", "-o", out, "--force")
    assert code == 0
    assert read_mesh(out).n_cells > 0


def bad_input(tmp_path, kind):
    path = tmp_path / "labels.npy"
    if kind == "missing":
        return tmp_path / "nope.npy"
    arrays = {
        "fraction": np.array([[0.0, 1.5], [1.0, 2.0]]),
        "one_d": np.array([0, 1, 1, 2]),
        "five_d": np.ones((2, 2, 2, 2, 2), dtype=np.uint8),
        "negative": np.array([[0, -1], [1, 2]]),
    }
    np.save(path, arrays[kind])
    return path


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("missing", "no image file at .*nope.npy"),
        ("fraction", "non-integer values"),
        ("one_d", "must be 2-D to 3-D; got 1-D"),
        ("five_d", "must be 2-D to 3-D; got 5-D"),
        ("negative", "negative values"),
    ],
)
def test_bad_labels_exit_2_with_one_clear_line(tmp_path, capsys, kind, message):
    path = bad_input(tmp_path, kind)
    code, stdout, stderr = run(capsys, "mesh", path, "-o", tmp_path / "m.vtu", "--json")
    assert code == 2
    assert stdout == ""
    assert len(stderr.strip().splitlines()) == 1
    assert stderr.startswith("swa-imesh mesh: error: ")
    assert re.search(message, stderr), stderr
    assert not (tmp_path / "m.vtu").exists()


def test_colour_picture_is_not_taken_for_a_volume(tmp_path, capsys):
    import imageio.v3 as iio

    rgb = np.zeros((8, 9, 3), dtype=np.uint8)
    rgb[2:5, 3:7] = (255, 0, 0)
    iio.imwrite(tmp_path / "photo.png", rgb)
    code, _, stderr = run(capsys, "mesh", tmp_path / "photo.png", "-o", tmp_path / "m.vtu")
    assert code == 2
    assert "colour picture" in stderr and "(8, 9, 3)" in stderr


def test_all_excluded_image_is_refused(tmp_path, capsys):
    np.save(tmp_path / "zeros.npy", np.zeros((4, 4), dtype=np.uint8))
    code, _, stderr = run(capsys, "mesh", tmp_path / "zeros.npy", "-o", tmp_path / "m.vtu",
                          "--exclude", "0")
    assert code == 2
    assert "excluded" in stderr and "nothing is left to mesh" in stderr
    assert not (tmp_path / "m.vtu").exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--spacing", "1", "2", "3"], "spacing must be one number or 2 numbers"),
        (["--spacing", "0"], "positive and finite"),
        (["--material-names", "bone"], "ID=NAME"),
        (["--material-names", "1=bone", "2=bone"], "share the name 'bone'"),
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, extra, message):
    np.save(tmp_path / "labels.npy", three_materials_2d())
    code, _, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / "m.msh",
                          *extra)
    assert code == 2
    assert message in stderr
    assert not (tmp_path / "m.msh").exists()


def test_unknown_output_suffix_fails_before_reading(tmp_path, capsys):
    code, _, stderr = run(capsys, "mesh", tmp_path / "missing.npy", "-o", tmp_path / "m.stl")
    assert code == 2
    assert "unknown suffix '.stl'" in stderr and ".vtu" in stderr


@pytest.mark.parametrize("dim", [2, 3])
def test_bounds_prints_the_quality_table(capsys, dim):
    code, stdout, _ = run(capsys, "bounds", "--dim", dim)
    assert code == 0
    assert "radius-to-edge" in stdout and "bound" in stdout


def test_bounds_json(capsys):
    code, stdout, _ = run(capsys, "bounds", "--dim", 2, "--json")
    assert code == 0
    report = one_json(stdout)
    assert report["dim"] == 2 and len(report["simplices"]) >= 1
    worst = max(row["radius_edge_ratio"] for row in report["simplices"])
    assert worst <= np.sqrt(5) / 2 + 1e-12  # within the reference's 2-D claim


def test_bounds_rejects_an_unsupported_dimension(capsys):
    code, _, stderr = run(capsys, "bounds", "--dim", "1")
    assert code == 2
    assert stderr.startswith("swa-imesh bounds: error:")


def test_no_check_skips_the_checks(tmp_path, capsys):
    import json

    import numpy as np


    lab = np.ones((16, 16), np.int32)
    lab[4:9, 5:12] = 2
    np.save(tmp_path / "lab.npy", lab)
    code = main(["mesh", str(tmp_path / "lab.npy"), "-o", str(tmp_path / "m.vtu"),
                 "--no-check", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["checks"] == {"skipped": True}
    assert "check" not in report["seconds"] or report["seconds"]["check"] == 0.0
    code = main(["mesh", str(tmp_path / "lab.npy"), "-o", str(tmp_path / "m2.vtu")])
    assert code == 0 and "conforming ok" in capsys.readouterr().out


# --------------------------------------------------- "no silent wrong result" cases


def test_too_large_for_memory_is_refused_before_meshing(tmp_path, capsys, monkeypatch):
    from napari_swa_imesh.mesh import _cli
    from napari_swa_imesh.mesh.mesher import _imesh

    np.save(tmp_path / "labels.npy", blob_3d())
    monkeypatch.setattr(_cli, "available_memory", lambda: 1000)
    monkeypatch.setattr(_cli, "current_rss", lambda: 0)
    monkeypatch.setattr(_imesh, "_mesh_labels", lambda *a, **k: pytest.fail("meshed"))
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o",
                               tmp_path / "m.vtu")
    assert code == 2 and stdout == ""
    assert len(stderr.strip().splitlines()) == 1
    assert re.search(r"needs .*about [0-9.]+ [MG]B of memory by the estimate, but 1000 bytes "
                     r"is available; crop .*--memory-limit", stderr), stderr
    assert not (tmp_path / "m.vtu").exists()


def test_memory_limit_option_and_estimate_in_json(tmp_path, capsys):
    np.save(tmp_path / "labels.npy", blob_3d())
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o",
                               tmp_path / "m.vtu", "--json", "--memory-limit", "64G")
    assert code == 0, stderr
    estimate = one_json(stdout)["memory_estimate_bytes"]
    assert isinstance(estimate, int) and estimate > 0
    code, _, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / "n.vtu",
                          "--memory-limit", "1M")
    assert code == 2 and "allowed by --memory-limit" in stderr
    code, _, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / "n.vtu",
                          "--memory-limit", "lots")
    assert code == 2 and "--memory-limit takes auto, off, or a size" in stderr
    code, _, _ = run(capsys, "mesh", tmp_path / "labels.npy", "-o", tmp_path / "n.vtu",
                     "--memory-limit", "off")
    assert code == 0


def test_a_1024_cube_is_refused_from_its_header_without_reading(tmp_path, capsys, monkeypatch):
    from napari_swa_imesh import io
    from napari_swa_imesh.mesh import _cli

    path = tmp_path / "big.npy"
    np.lib.format.open_memmap(path, mode="w+", dtype=np.uint8, shape=(1024,) * 3).flush()
    monkeypatch.setattr(_cli, "available_memory", lambda: 2 * 2**30)
    monkeypatch.setattr(io, "read_image", lambda *a, **k: pytest.fail("read the pixels"))
    code, _, stderr = run(capsys, "mesh", path, "-o", tmp_path / "m.vtu")
    assert code == 2
    assert "1024x1024x1024 uint8" in stderr and "needs at least about" in stderr


def test_memory_error_is_one_line_with_what_to_do(tmp_path, capsys, monkeypatch):
    from napari_swa_imesh.mesh.mesher import _imesh

    def boom(*args, **kwargs):
        raise MemoryError("Unable to allocate 8.00 GiB for an array with shape "
                          "(1073741824,) and data type int64")

    np.save(tmp_path / "labels.npy", blob_3d())
    monkeypatch.setattr(_imesh, "_mesh_labels", boom)
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o",
                               tmp_path / "m.vtu")
    assert code == 2 and stdout == ""
    assert stderr.strip() == (
        "swa-imesh mesh: error: ran out of memory (an allocation of 8.00 GiB failed); crop "
        "the image, coarsen (downsample) it, or work on a sub-volume, or run on a machine "
        "with more memory.")


def test_memory_limit_of_the_process_is_respected(tmp_path):
    """Under ulimit -v the run is refused by the estimate (exit 2), never a traceback."""
    import os
    import subprocess
    import sys

    rng = np.random.default_rng(0)
    np.save(tmp_path / "noise.npy", rng.integers(0, 4, (64, 64, 64)).astype(np.uint8))
    script = ("import resource, sys; from napari_swa_imesh.cli import main; "
              "import napari_swa_imesh.mesh.mesher._imesh, napari_swa_imesh.io; "
              "resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[1]), int(sys.argv[1]))); "
              "sys.exit(main(sys.argv[2:]))")
    # the address space taken after importing, plus 300 MB: too little for 64^3 noise
    probe = subprocess.run([sys.executable, "-c",
                            "import napari_swa_imesh.cli, napari_swa_imesh.mesh.mesher._imesh, "
                            "napari_swa_imesh.io; print(open('/proc/self/status').read())"],
                           capture_output=True, text=True, env=os.environ.copy())
    vm = next(int(line.split()[1]) * 1024 for line in probe.stdout.splitlines()
              if line.startswith("VmSize:"))
    proc = subprocess.run([sys.executable, "-c", script, str(vm + 300 * 2**20), "mesh",
                           str(tmp_path / "noise.npy"), "-o", str(tmp_path / "m.vtu")],
                          capture_output=True, text=True, env=os.environ.copy())
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "of memory by the estimate" in proc.stderr, proc.stderr


def test_spacing_that_overflows_or_underflows_exit_2(tmp_path, capsys):
    np.save(tmp_path / "labels.npy", blob_3d())
    for value in ("1e-300", "1e300"):
        code, _, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o",
                              tmp_path / "m.vtu", "--spacing", value)
        assert code == 2 and "other units" in stderr and "np.float64" not in stderr
        assert not (tmp_path / "m.vtu").exists()


def test_mesh_command_builds_one_tree_and_one_balance(tmp_path, capsys, monkeypatch):
    # the checks reuse the mesher's region tree, and the face-only balance count (a
    # second balance pass) is not made just to fill a report field
    from napari_swa_imesh.mesh.checks import _checks
    from napari_swa_imesh.mesh.mesher import _imesh

    monkeypatch.setattr(_checks, "_build_tree", lambda *a, **k: pytest.fail("second tree"))
    monkeypatch.setattr(_imesh, "count_balanced_leaves",
                        lambda *a, **k: pytest.fail("second balance pass"))
    np.save(tmp_path / "labels.npy", blob_3d())
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "labels.npy", "-o",
                               tmp_path / "m.vtu", "--json", "--exclude", "0", "0")
    assert code == 0, stderr
    report = one_json(stdout)
    assert report["checks"]["all_passed"] is True and report["exclude"] == [0]
    assert "face_balance_count" not in report["seconds"]["mesh_steps"]


def test_mesh_order_2_with_chosen_facet_groups_as_ascii_gmsh(tmp_path, capsys):
    import meshio

    np.save(tmp_path / "vol.npy", blob_3d())
    out = tmp_path / "vol.msh"
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "vol.npy", "-o", out, "--order", "2",
                               "--facet-groups", "xmin,interface_*", "--msh-ascii", "--json")
    assert code == 0, stderr
    assert one_json(stdout)["order"] == 2
    assert out.read_bytes().startswith(b"$MeshFormat\n4.1 0 8\n")
    m = meshio.read(out)
    assert {b.type for b in m.cells} == {"tetra10", "triangle6"}
    facet_groups = {n for n, (_, d) in m.field_data.items() if d == 2}
    assert facet_groups == {"xmin", "interface_material_0_material_1",
                            "interface_material_0_material_2", "interface_material_1_material_2"}


def test_mesh_facet_groups_none_writes_the_vtu_alone(tmp_path, capsys):
    np.save(tmp_path / "l.npy", three_materials_2d())
    code, stdout, stderr = run(capsys, "mesh", tmp_path / "l.npy", "-o", tmp_path / "m.vtu",
                               "--facet-groups", "none", "--json")
    assert code == 0, stderr
    assert one_json(stdout)["output"] == [str(tmp_path / "m.vtu")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy", "m.vtu"]


@pytest.mark.parametrize(("flags", "match"), [
    (["--facet-groups", "zmin"], "unknown facet group 'zmin'; the groups are xmin, xmax, "
                                 "ymin, ymax,"),
    (["--order", "3"], "--order must be 1 or 2, not '3'"),
    (["--msh-ascii"], "--msh-ascii applies to .msh output only"),
])
def test_mesh_write_options_fail_before_meshing(tmp_path, capsys, monkeypatch, flags, match):
    import napari_swa_imesh.mesh.mesher._imesh as imesh

    def no_meshing(*args, **kwargs):
        raise AssertionError("meshed before checking the options")

    monkeypatch.setattr(imesh, "_mesh_labels", no_meshing)
    np.save(tmp_path / "l.npy", three_materials_2d())
    code, _, stderr = run(capsys, "mesh", tmp_path / "l.npy", "-o", tmp_path / "m.vtu", *flags)
    assert code == 2 and re.search(re.escape(match), stderr), stderr


def test_checks_beside_the_writer_give_the_files_and_verdict_of_one_after_the_other(
        tmp_path, capsys):
    """The command checks on a second thread while it writes: its files are byte for
    byte those the library writes alone, and its checks those check_mesh gives."""
    from napari_swa_imesh.mesh.checks._checks import check_mesh
    from napari_swa_imesh.mesh.formats._export import write_mesh
    from napari_swa_imesh.mesh.mesher._imesh import mesh_labels

    lab = (np.indices((12, 10, 9)).sum(0) // 6 + (np.arange(9) % 4 == 0)).astype(np.uint8)
    np.save(tmp_path / "lab.npy", lab)
    code, stdout, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "cmd.vtu",
                          "--json")
    assert code == 0
    mesh = mesh_labels(lab)
    write_mesh(mesh, tmp_path / "lib.vtu")
    for a, b in (("cmd.vtu", "lib.vtu"), ("cmd_facets.vtu", "lib_facets.vtu")):
        assert (tmp_path / a).read_bytes() == (tmp_path / b).read_bytes()
    report = one_json(stdout)
    assert report["checks"] == check_mesh(mesh, lab).to_dict()
    assert report["seconds"]["check"] > 0 and report["seconds"]["write"] > 0


def test_full_check_sorts_and_agrees_with_the_default(tmp_path, capsys, monkeypatch):
    """--full-check takes the sort of every facet (the one-pass check is never called)
    and reports what the default does."""
    from napari_swa_imesh.mesh.checks import _checks

    lab = (np.indices((9, 8, 7)).sum(0) // 5).astype(np.uint8)
    np.save(tmp_path / "lab.npy", lab)
    code, stdout, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "a.vtu",
                          "--json")
    assert code == 0
    default = one_json(stdout)["checks"]

    def refused(*args):
        raise AssertionError("the one-pass check ran under --full-check")

    monkeypatch.setattr(_checks, "lattice_checks", refused)
    code, stdout, _ = run(capsys, "mesh", tmp_path / "lab.npy", "-o", tmp_path / "b.vtu",
                          "--json", "--full-check")
    assert code == 0 and one_json(stdout)["checks"] == default and default["all_passed"]
