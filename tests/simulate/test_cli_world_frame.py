"""``swa-imesh simulate`` on a NIfTI label file writes its meshes in the world frame of the
affine, as ``swa-imesh mesh`` does (docs/formats.md): the steady field, the transient
series and the growth series; the growth seed is then given in world coordinates."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import world_from_affine

SCALED = np.diag([2.0, 1.0, 1.0, 1.0])
SCALED[:3, 3] = (100, 200, 300)
ROTATED = np.array([[0.0, -1.0, 0.0, 10.0],     # 90 degrees about z, then a shift
                    [1.0, 0.0, 0.0, -5.0],
                    [0.0, 0.0, 1.0, 7.0],
                    [0.0, 0.0, 0.0, 1.0]])


def _labels() -> np.ndarray:
    labels = np.full((6, 5, 6), 2, dtype=np.uint8)
    labels[:3] = 1                              # material 1 on the low half of axis 0
    return labels


@pytest.fixture(params=[SCALED, ROTATED], ids=["scaled", "rotated"])
def nifti(request, tmp_path):
    nib = pytest.importorskip("nibabel")
    path = tmp_path / "labels.nii.gz"
    nib.save(nib.Nifti1Image(_labels(), request.param), str(path))
    return path, request.param


def _run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert rc == 0, err
    return out


def _box(points: np.ndarray) -> np.ndarray:
    return np.stack([points.min(axis=0), points.max(axis=0)])


def _mesh_box(capsys, path) -> np.ndarray:
    import meshio

    out = path.parent / "mesh.vtu"
    _run(capsys, "mesh", path, "-o", out)
    return _box(meshio.read(out).points)


def _series_box(path) -> np.ndarray:
    import meshio

    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, _ = reader.read_points_cells()
    return _box(points)


def test_the_steady_field_is_in_the_world_frame_of_mesh(nifti, capsys):
    import meshio

    path, affine = nifti
    expected = _mesh_box(capsys, path)
    assert not np.allclose(expected, _box(np.indices((7, 6, 7)).reshape(3, -1).T))
    out = path.parent / "field.vtu"
    _run(capsys, "simulate", path, "-k", "1=1", "2=10", "--axes", "x", "-o", out)
    np.testing.assert_allclose(_box(meshio.read(out).points), expected, atol=1e-9)


def test_the_transient_series_is_in_the_world_frame_of_mesh(nifti, capsys):
    path, _ = nifti
    expected = _mesh_box(capsys, path)
    out = path.parent / "series.xdmf"
    _run(capsys, "simulate", path, "-k", "1=1", "2=10", "--transient", "1", "--steps", "2",
         "--fixed", "xmin=1", "-o", out)
    np.testing.assert_allclose(_series_box(out), expected, atol=1e-9)


def _growth(capsys, path, seed: str, out, *extra) -> dict:
    out.parent.mkdir()
    text = _run(capsys, "simulate", path, *extra, "--model", "fisher-kpp", "-D", "1=1",
                "2=0.5", "--rate", "1", "--seed", seed, "--duration", "0.5", "--steps", "1",
                "--front-cells", "1", "-o", out, "--json")
    with open(out.with_suffix(".csv"), newline="") as f:
        first = next(csv.DictReader(f))
    return {**json.loads(text), "first": first}


def test_growth_is_in_the_world_frame_and_its_seed_in_world_coordinates(nifti, capsys,
                                                                        tmp_path):
    path, affine = nifti
    expected = _mesh_box(capsys, path)
    spacing, world = world_from_affine(affine, 3)
    npy = tmp_path / "labels.npy"
    np.save(npy, _labels())
    # the seed ball inside material 1 (axis-0 index < 3), in the .npy's own frame ...
    mesh_centre = np.array([1.5, 2.5, 3.0]) * spacing     # array order, spacing applied
    index_seed = ",".join(f"{v:g}" for v in mesh_centre[::-1]) + ":1.4"
    # ... and the same ball in world x, y, z for the NIfTI file
    world_centre = world[:3, :3] @ mesh_centre + world[:3, 3]
    world_seed = ",".join(f"{v:.12g}" for v in world_centre) + ":1.4"
    placed = _growth(capsys, path, world_seed, tmp_path / "nifti" / "growth.xdmf")
    np.testing.assert_allclose(_series_box(tmp_path / "nifti" / "growth.xdmf"), expected,
                               atol=1e-9)
    ref = _growth(capsys, npy, index_seed, tmp_path / "npy" / "growth.xdmf",
                  "--spacing", *(f"{v:g}" for v in spacing))
    assert float(ref["first"]["volume_1"]) > 0 and float(ref["first"]["volume_2"]) == 0
    assert float(placed["first"]["volume_1"]) == pytest.approx(float(ref["first"]["volume_1"]))
    assert float(placed["first"]["volume_2"]) == 0
    assert placed["volume"] == pytest.approx(ref["volume"])
    assert float(placed["first"]["amount"]) == pytest.approx(float(ref["first"]["amount"]))
