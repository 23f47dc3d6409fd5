"""``swa-imesh demo``, the README's first command, run as a user runs it."""

from __future__ import annotations

import json
import subprocess
import sys

import meshio
import numpy as np
import pytest
import tifffile

from napari_swa_imesh._demo import DEMO_FILES


def _demo(*args, cwd):
    return subprocess.run([sys.executable, "-m", "napari_swa_imesh.cli", "demo", *args],
                          capture_output=True, text=True, cwd=cwd)


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_demo_runs_the_whole_pipeline_and_refuses_to_overwrite(tmp_path):
    proc = _demo("--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    out = tmp_path / "swa-imesh-demo"
    assert sorted(p.name for p in out.iterdir()) == sorted(DEMO_FILES)

    # the printed Dice is the Dice of the files left behind
    labels = tifffile.imread(out / "labels.tif")
    truth = tifffile.imread(out / "truth.tif")
    for value, dice in report["dice"].items():
        a, b = labels == int(value), truth == int(value)
        assert abs(2 * np.sum(a & b) / (a.sum() + b.sum()) - dice) < 1e-9
    assert report["mean_dice"] > 0.9

    # the mesh is the labels' mesh: triangles cover the image, materials by area
    mesh = meshio.read(out / "mesh.vtu")
    tri = mesh.cells_dict["triangle"]
    p = mesh.points[tri][:, :, :2]
    u, v = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    assert area.sum() == labels.size
    assert report["mesh"]["elements"] == len(tri)
    assert report["mesh"]["checks_passed"] is True

    # k_eff of the field left behind: the mesh's, within its bounds, the field readable
    sim = report["simulate"]
    for axis, k in sim["k_eff"].items():
        lo, hi = sim["bounds"][axis]
        assert lo < k < hi
    field = meshio.read(out / "field.vtu")
    assert {"potential_x", "potential_y"} <= set(field.point_data)
    assert field.point_data["potential_x"].min() == pytest.approx(0, abs=1e-9)

    before = _snapshot(out)
    again = _demo(cwd=tmp_path)
    assert again.returncode == 2
    assert again.stderr.count("\n") == 1 and "--force" in again.stderr
    assert _snapshot(out) == before

    # the text output defines the jargon it prints (eps_m is charged for the feature count)
    text = _demo("--force", cwd=tmp_path)
    assert text.returncode == 0, text.stderr
    printed, terms = text.stdout.split("\nterms:\n")
    from napari_swa_imesh._glossary import define, terms_in

    assert {"eps_l", "eps_m", "k_eff", "radius-to-edge ratio"} <= set(terms_in(printed))
    for term in terms_in(printed):
        assert f"{term}: {define(term)}" in terms
    assert "eps_m = " in printed and "-#F x eps_l / 100" in printed
