"""Block-wise meshing on a subdivided lattice and under a size cap (issue 27): the same
mesh as the in-memory mesher's for anisotropic voxels, --no-subdivide and --max-size."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import mesh_labels, read_mesh
from napari_swa_imesh.mesh.blocks import mesh_blocks


def _volume(shape=(12, 18, 20), seed=2):
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.int64)
    lab[2:10, 3:15, 2:18] = 1
    lab[5:12, 8:12, :] = 2
    lab[rng.random(shape) < 0.02] = 3
    return lab


def _keys(points, cells, step):
    """Elements as sorted rows of their corners' lattice keys (points / step), sorted."""
    pts = np.rint(np.asarray(points) / np.asarray(step)).astype(np.int64)
    assert np.allclose(pts * np.asarray(step), points)        # points on the lattice
    flat = pts @ (np.int64(1 << 20) ** np.arange(pts.shape[1] - 1, -1, -1))
    keys = np.sort(flat[cells], axis=1)
    return keys[np.lexsort(keys.T[::-1])]


@pytest.mark.parametrize("kw", [
    {"spacing": (2.5, 1.0, 1.0)},                       # voxels cut 2 x 1 x 1 (or more)
    {"spacing": (1.0, 0.5, 1.5), "subdivide": False},   # stretched templates
    {"spacing": (1.0, 1.0, 1.0), "max_size": 2.0},      # leaves of 1 cell (diagonal 1.73)
    {"spacing": (3.0, 1.0, 1.0), "max_size": 8.0},
])
def test_the_pieces_are_the_in_memory_mesh(tmp_path, kw):
    lab = _volume()
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=8, workers=0, exclude=(0,), **kw)
    ref = mesh_labels(lab, exclude=(0,), **kw)
    step = ref.recipe.lattice.step
    assert tuple(report["lattice"]["step"]) == pytest.approx(step)
    got = read_mesh(tmp_path / "m.pvtu")
    assert got.n_cells == ref.n_cells == report["n_elements"]
    assert np.array_equal(_keys(got.points, got.cells, step), _keys(ref.points, ref.cells, step))
    # physical volumes exact per material, worst ratio within the bound and the reference
    voxel = float(np.prod(kw["spacing"]))
    for m in (1, 2, 3):
        assert report["volumes"][m] == pytest.approx(np.count_nonzero(lab == m) * voxel)
    assert report["worst_ratio"] <= report["quality_bound"] * (1 + 1e-12)
    assert report["worst_ratio"] == pytest.approx(float(ref.quality.max()))


def test_the_command_line_takes_spacing_and_max_size(tmp_path, capsys):
    lab = _volume()
    np.save(tmp_path / "l.npy", lab.astype(np.uint8))
    out = tmp_path / "m.pvtu"
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(out), "--workers", "0",
                 "--exclude", "0", "--spacing", "2.5", "1", "1", "--max-size", "6"]) == 0
    assert read_mesh(out).n_cells == mesh_labels(lab, exclude=(0,), spacing=(2.5, 1, 1),
                                                 max_size=6).n_cells
    capsys.readouterr()
    # still refused, before any work: one sentence naming the option
    for option in (["--method", "delaunay"], ["--full-check"]):
        code = main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "n.pvtu"),
                     "--workers", "0"] + option)
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and f"{option[0]} is not available" in err
    assert not (tmp_path / "n.pvtu").exists()
