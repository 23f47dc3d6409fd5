"""Meshing a mesh's labels again for a refine level or periodic faces, as it was made."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels, to_meshio
from napari_swa_imesh.simulate import simulate
from napari_swa_imesh.simulate._remesh import mesh_refine, needs_remesh, remesh


@pytest.fixture
def labels():
    rng = np.random.default_rng(4)
    lab = rng.integers(1, 3, (5, 6, 7)).astype(np.uint8)
    lab[2, 2:4, 2:4] = 3
    return lab


def _same_mesh(a, b):
    assert a.n_cells == b.n_cells
    assert np.array_equal(np.sort(a.points, axis=0), np.sort(b.points, axis=0))
    assert np.array_equal(np.sort(a.material), np.sort(b.material))


def test_remesh_keeps_every_setting_but_refine_and_periodic(labels):
    kwargs = {"exclude": [3], "spacing": (2.0, 1.0, 1.0), "max_size": 3.0,
              "material_names": {1: "a", 2: "b"}}
    mesh = mesh_labels(labels, **kwargs)
    assert mesh_refine(mesh) == 0
    new = remesh(mesh, labels, refine=1, periodic=True)
    _same_mesh(new, mesh_labels(labels, **kwargs, refine=1, periodic=True))
    assert mesh_refine(new) == 1 and new.recipe.periodic and new.material_names == {1: "a",
                                                                                    2: "b"}
    assert 3 not in new.material
    # without anisotropy subdivision, the new mesh is cut on the voxels too
    flat = mesh_labels(labels, spacing=(2.0, 1.0, 1.0), subdivide=False)
    _same_mesh(remesh(flat, labels, refine=1, periodic=False),
               mesh_labels(labels, spacing=(2.0, 1.0, 1.0), subdivide=False, refine=1))


def test_the_remeshed_run_equals_simulating_the_labels(labels):
    k = {1: 1.0, 2: 5.0, 3: 0.5}
    mesh = mesh_labels(labels, spacing=(1.5, 1.0, 1.0))
    new = remesh(mesh, labels, refine=1, periodic=True)
    ours = simulate(new, k, protocol="periodic", axes="x")
    direct = simulate(labels, k, spacing=(1.5, 1.0, 1.0), refine=1, protocol="periodic",
                      axes="x", adapt=0)
    assert ours.k_eff["x"] == pytest.approx(direct.k_eff["x"], rel=1e-9)
    assert np.allclose(ours.tensor[:, 0], direct.tensor[:, 0], rtol=1e-9)


def test_the_world_placement_is_kept():
    labels = np.ones((3, 4, 5), dtype=np.uint8)
    labels[:, :, 3:] = 2
    affine = np.array([[0.0, 0.0, -2.0, 10.0], [0.0, 1.0, 0.0, -3.0],
                       [1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]])
    mesh = mesh_labels(labels, affine=affine)
    new = remesh(mesh, labels, refine=1, periodic=False)
    expected = to_meshio(mesh_labels(labels, affine=affine, refine=1)).points
    assert np.allclose(np.sort(to_meshio(new).points, axis=0), np.sort(expected, axis=0))


def test_when_a_new_mesh_is_needed(labels):
    mesh = mesh_labels(labels)
    assert not needs_remesh(mesh, refine=0, periodic=False)
    assert needs_remesh(mesh, refine=2, periodic=False)
    assert needs_remesh(mesh, refine=0, periodic=True)
    periodic = mesh_labels(labels, refine=1, periodic=True)
    assert not needs_remesh(periodic, refine=1, periodic=False)
    assert not needs_remesh(periodic, refine=1, periodic=True)
    assert needs_remesh(periodic, refine=0, periodic=True)


def test_labels_that_are_not_the_mesh_image_are_refused(labels):
    mesh = mesh_labels(labels)
    with pytest.raises(ValueError,
                       match=r"the labels are \(6, 6\) but the mesh was made from \(5, 6, 7\)"):
        remesh(mesh, labels[0, :, :6], refine=1, periodic=False)
    other = labels.copy()
    other[0, 0, 0] = 3 - other[0, 0, 0]              # same shape, one voxel swapped
    with pytest.raises(ValueError, match="other material volumes"):
        remesh(mesh, other, refine=1, periodic=False)
    coarse = mesh_labels(labels, coarsen=1)
    with pytest.raises(ValueError, match="coarsened"):
        remesh(coarse, labels, refine=1, periodic=False)


def test_a_mesh_read_from_a_file_is_not_meshed_again(labels, tmp_path):
    from napari_swa_imesh.mesh import read_mesh, write_mesh

    write_mesh(mesh_labels(labels), tmp_path / "m.vtu")
    read = read_mesh(tmp_path / "m.vtu")
    assert not read.records_box
    with pytest.raises(ValueError, match="does not record the label image"):
        remesh(read, labels, refine=1, periodic=False)
