"""``swa-imesh mesh`` on NIfTI files: world coordinates by default, ``--index-space`` for the
image's own frame, and the refusals; other formats keep voxel corner 0 at the origin."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from napari_swa_imesh.io import read_image, write_labels
from napari_swa_imesh.mesh import signed_volumes
from swa_cli_helpers import run

nib = pytest.importorskip("nibabel")
apply_affine = nib.affines.apply_affine


def labels_3d() -> np.ndarray:
    rng = np.random.default_rng(5)
    labels = np.ones((6, 7, 5), np.uint8)
    labels[1:5, 2:6, 1:4] = 2
    labels[rng.random(labels.shape) < 0.06] = 3
    return labels


def oblique_flipped_affine(ndim: int = 3) -> np.ndarray:
    """Oblique rotation with a flip (determinant < 0), anisotropic voxels, an origin."""
    q, r = np.linalg.qr(np.random.default_rng(11).normal(size=(ndim, ndim)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) > 0:
        q[:, 1] = -q[:, 1]
    affine = np.eye(ndim + 1)
    affine[:ndim, :ndim] = q @ np.diag([0.8, 1.5, 2.5][:ndim])
    affine[:ndim, ndim] = [31.0, -12.0, 4.5][:ndim]
    return affine


def save_nifti(path, labels, affine) -> np.ndarray:
    """Save and return the affine as nibabel reads it back (NIfTI stores float32)."""
    if affine.shape[0] == 3:                          # 2-D image: NIfTI stores 4 x 4
        full = np.eye(4)
        full[:2, :2], full[:2, 3] = affine[:2, :2], affine[:2, 2]
        affine = full
    nib.save(nib.Nifti1Image(labels, affine), str(path))
    return nib.load(str(path)).affine


def mesh_file(capsys, src, out, *options) -> tuple[meshio.Mesh, dict]:
    code, stdout, stderr = run(capsys, "mesh", src, "-o", out, "--json", *options)
    assert code == 0, stderr
    return meshio.read(out), json.loads(stdout)


@pytest.mark.parametrize("ndim", [2, 3])
def test_nifti_mesh_lies_where_nibabel_puts_the_voxels(tmp_path, capsys, ndim):
    labels = labels_3d() if ndim == 3 else labels_3d()[2]
    affine = save_nifti(tmp_path / "l.nii.gz", labels, oblique_flipped_affine(ndim))
    world, report = mesh_file(capsys, tmp_path / "l.nii.gz", tmp_path / "w.vtu")
    image, image_report = mesh_file(capsys, tmp_path / "l.nii.gz", tmp_path / "i.vtu",
                                    "--index-space")
    assert report["frame"] == "world" and image_report["frame"] == "image"
    assert report["checks"]["all_passed"] is True
    # --index-space: x, y(, z) = column, row(, plane) times the voxel sizes of the affine
    # (the norms of its columns, as the world frame uses them), corner 0 at 0
    zooms = np.linalg.norm(affine[:3, :ndim], axis=0)
    assert read_image(tmp_path / "l.nii.gz")[1] == tuple(zooms)
    corner = image.points[:, :ndim][:, ::-1] / zooms  # (N, d) corner index per array axis
    assert corner.min() == 0 and np.allclose(corner.max(axis=0), labels.shape)
    on_corner = np.all(np.abs(corner - np.round(corner)) < 1e-9, axis=1)
    assert on_corner.mean() > 0.1          # anisotropic voxels: lattice points inside too
    # the same vertices (same order) in the world file: nibabel's voxel-corner positions
    points = world.points[:, :3] if ndim == 3 else world.points[:, :2]
    expected = apply_affine(affine, np.column_stack(
        [np.round(corner[on_corner]) - 0.5] + ([np.zeros(on_corner.sum())] if ndim == 2
                                                else [])))[:, :ndim]
    np.testing.assert_allclose(points[on_corner], expected, atol=1e-6)
    # each material's volume in world units, every element positive
    volumes = signed_volumes(points, world.cells[0].data)
    assert (volumes > 0).all()
    voxel = abs(np.linalg.det(affine[:ndim, :ndim]))
    material = world.cell_data["material"][0]
    for value in np.unique(labels):
        assert volumes[material == value].sum() == pytest.approx(
            np.count_nonzero(labels == value) * voxel, rel=1e-9)


def test_index_space_is_the_npy_mesh_at_the_voxel_sizes_of_the_affine(tmp_path, capsys):
    labels = labels_3d()
    affine = save_nifti(tmp_path / "l.nii.gz", labels, oblique_flipped_affine())
    # the sform's column norms (not pixdim, which may differ from them in float32's last
    # digit): the spacing of the world frame and of every command reading the file
    zooms = [repr(float(z)) for z in np.linalg.norm(affine[:3, :3], axis=0)]
    np.save(tmp_path / "l.npy", labels)
    from_nifti, _ = mesh_file(capsys, tmp_path / "l.nii.gz", tmp_path / "a.vtu",
                              "--index-space")
    from_npy, _ = mesh_file(capsys, tmp_path / "l.npy", tmp_path / "b.vtu", "--spacing",
                            *zooms)
    np.testing.assert_array_equal(from_nifti.points, from_npy.points)


@pytest.mark.parametrize("suffix", [".tif", ".npy"])
def test_other_formats_keep_corner_zero_at_the_origin(tmp_path, capsys, suffix):
    labels = labels_3d()
    spacing = (2.0, 1.0, 0.5)
    write_labels(tmp_path / f"l{suffix}", labels, spacing=spacing)
    extra = ["--spacing", *spacing] if suffix == ".npy" else []
    m, report = mesh_file(capsys, tmp_path / f"l{suffix}", tmp_path / "m.vtu", *extra)
    assert report["frame"] == "image" and report["world"] is None
    np.testing.assert_allclose(m.points.min(axis=0), 0.0)
    np.testing.assert_allclose(m.points.max(axis=0), np.multiply(labels.shape, spacing)[::-1])


def refused(capsys, tmp_path, *argv) -> str:
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = run(capsys, "mesh", *argv)
    assert code == 2, err
    lines = [line for line in err.splitlines() if ": error: " in line]
    assert len(lines) == 1 and "Traceback" not in err and out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    return lines[0]


@pytest.mark.parametrize("suffix", [".npy", ".tif"])
def test_index_space_without_an_affine_is_refused(tmp_path, capsys, suffix):
    write_labels(tmp_path / f"l{suffix}", labels_3d())
    line = refused(capsys, tmp_path, tmp_path / f"l{suffix}", "-o", tmp_path / "m.vtu",
                   "--index-space")
    assert f"--index-space applies to NIfTI files (.nii, .nii.gz), whose affine places the " \
           f"mesh; l{suffix} has none" in line


def test_singular_affine_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    import napari_swa_imesh.io as io

    header = nib.Nifti1Header()
    header.set_data_shape((3, 4, 5))
    header.set_data_dtype(np.uint8)
    header.set_sform(np.diag([1.0, 0.0, 1.0, 1.0]), code=2)
    nib.save(nib.Nifti1Image(np.ones((3, 4, 5), np.uint8), None, header=header),
             str(tmp_path / "flat.nii.gz"))

    def no_pixels(*args, **kwargs):
        raise AssertionError("the pixels were read before the affine was checked")

    monkeypatch.setattr(io, "read_image", no_pixels)
    line = refused(capsys, tmp_path, tmp_path / "flat.nii.gz", "-o", tmp_path / "m.vtu")
    # the reader's one rule for every command (issue 22): --index-space cannot help, the
    # file gives no voxel size either
    assert "the sform of flat.nii.gz is singular" in line and "fix the sform" in line


def test_spacing_with_a_nifti_affine_is_refused(tmp_path, capsys):
    save_nifti(tmp_path / "l.nii.gz", labels_3d(), oblique_flipped_affine())
    line = refused(capsys, tmp_path, tmp_path / "l.nii.gz", "-o", tmp_path / "m.vtu",
                   "--spacing", "1")
    assert "--spacing conflicts with the affine of l.nii.gz" in line
    code, _, err = run(capsys, "mesh", tmp_path / "l.nii.gz", "-o", tmp_path / "m.vtu",
                       "--spacing", "1", "--index-space")
    assert code == 0, err


def test_tilted_2d_nifti_is_refused(tmp_path, capsys):
    affine = np.eye(4)
    affine[2, 0] = 0.5                                 # z changes along the first axis
    nib.save(nib.Nifti1Image(labels_3d()[0], affine), str(tmp_path / "t.nii.gz"))
    line = refused(capsys, tmp_path, tmp_path / "t.nii.gz", "-o", tmp_path / "m.vtu")
    assert "tilts the 2-D image out of the world's x-y plane" in line
    code, _, err = run(capsys, "mesh", tmp_path / "t.nii.gz", "-o", tmp_path / "m.vtu",
                       "--index-space")
    assert code == 0, err


def test_sheared_affine_is_placed_with_a_warning(tmp_path, capsys):
    affine = np.diag([1.0, 1.0, 2.0, 1.0])
    affine[0, 1] = 0.3
    affine = save_nifti(tmp_path / "s.nii.gz", labels_3d(), affine)
    code, out, err = run(capsys, "mesh", tmp_path / "s.nii.gz", "-o", tmp_path / "m.vtu")
    assert code == 0, err
    assert "swa-imesh mesh: warning: the affine of s.nii.gz shears the voxels" in err
    assert "world frame of the NIfTI affine" in out
    m = meshio.read(tmp_path / "m.vtu")
    lo = apply_affine(affine, np.array(np.meshgrid(*[[-0.5, n - 0.5] for n in (6, 7, 5)],
                                                   indexing="ij")).reshape(3, -1).T)
    np.testing.assert_allclose(m.points.min(axis=0), lo.min(axis=0), atol=1e-6)
    np.testing.assert_allclose(m.points.max(axis=0), lo.max(axis=0), atol=1e-6)


@pytest.mark.parametrize("tiles", [False, True])
def test_labels_segmented_from_a_nifti_image_keep_its_world(tmp_path, capsys, tiles):
    from napari_swa_imesh.segmentation import Samples, save_samples

    rng = np.random.default_rng(0)
    truth = np.ones((48, 64), np.int64)
    truth[:, 32:] = 2
    image = np.array([0, 10.0, 14.0])[truth] + rng.standard_normal(truth.shape)
    affine = np.eye(4)
    affine[:2, :2] = oblique_flipped_affine(2)[:2, :2]
    affine[:3, 3] = [3.0, -2.0, 9.0]
    affine = save_nifti(tmp_path / "img.nii.gz", image.astype(np.float32), affine)
    save_samples(Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [48, 28]},
        {"label": 2, "start": [0, 36], "stop": [48, 64]}]}), tmp_path / "s.json")
    code, _, err = run(capsys, "segment", tmp_path / "img.nii.gz", "--samples",
                       tmp_path / "s.json", "--method", "reference", "--scale", 2,
                       *(["--tiles"] if tiles else []), "-o", tmp_path / "lab.nii.gz")
    assert code == 0, err
    step = 4 if tiles else 1
    got = nib.load(str(tmp_path / "lab.nii.gz")).affine
    # label t's centre is the centre of the pixels it covers, where the image put them
    for index in ([0, 0], [3, 5], [11, 15]):
        centre = np.multiply(index, step) + (step - 1) / 2
        np.testing.assert_allclose(apply_affine(got, index + [0]),
                                   apply_affine(affine, list(centre) + [0]), atol=1e-5)
    # and the mesh of the labels covers the image's world box
    m, report = mesh_file(capsys, tmp_path / "lab.nii.gz", tmp_path / "m.vtu")
    assert report["frame"] == "world"
    corners = apply_affine(affine, np.array([[-0.5, -0.5, 0], [47.5, -0.5, 0], [-0.5, 63.5, 0],
                                             [47.5, 63.5, 0]]))[:, :2]
    np.testing.assert_allclose(m.points[:, :2].min(axis=0), corners.min(axis=0), atol=1e-5)
    np.testing.assert_allclose(m.points[:, :2].max(axis=0), corners.max(axis=0), atol=1e-5)


def test_write_labels_refuses_an_affine_it_cannot_hold(tmp_path):
    with pytest.raises(ValueError, match="an affine can only be written to NIfTI"):
        write_labels(tmp_path / "l.tif", np.ones((2, 3), np.uint8), affine=np.eye(4))
    assert list(tmp_path.iterdir()) == []
