"""A simulation on a mesh placed in a world frame writes its flux in that frame too."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import simulate, write_field


@pytest.mark.parametrize("suffix", [".vtu", ".xdmf"])
def test_flux_turns_with_the_points(tmp_path, suffix):
    # x flipped and the column axis along world y: potential 0 -> 1 along the columns
    affine = np.array([[-2.0, 0, 0, 5], [0, 0, 1.5, 0], [0, 1, 0, -3], [0, 0, 0, 1]])
    labels = np.ones((3, 4, 5), np.uint8)
    mesh = mesh_labels(labels, affine=affine)
    result = simulate(mesh, {1: 2.0}, axes="x")
    written = write_field(result, tmp_path / f"f{suffix}")
    m = meshio.read(written[0])
    length = labels.shape[2] * 1.5                    # along the column axis
    flux = m.cell_data["flux_x"][0]
    # -k grad u, grad u = 1/length along the column axis, which the affine sends to +y
    np.testing.assert_allclose(flux, np.tile([0.0, -2.0 / length, 0.0], (len(flux), 1)),
                               atol=1e-9)
    assert m.points[:, 1].max() - m.points[:, 1].min() == pytest.approx(length)


def test_simulating_a_mesh_file_in_a_rotated_world_frame_is_refused(tmp_path):
    from napari_swa_imesh.mesh import mesh_labels, read_mesh, write_mesh
    from napari_swa_imesh.simulate import simulate

    labels = np.ones((6, 7, 8), np.uint8)
    labels[:, :, 4:] = 2
    affine = np.eye(4)
    c, s = np.cos(0.5), np.sin(0.5)
    affine[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    affine[:3, 3] = [10, -5, 3]
    write_mesh(mesh_labels(labels, affine=affine), tmp_path / "world.vtu")
    with pytest.raises(ValueError, match="not an axis-aligned box"):
        simulate(read_mesh(tmp_path / "world.vtu"), {1: 1.0, 2: 3.0})
    # the same mesh in the image frame gives the series mean exactly
    write_mesh(mesh_labels(labels), tmp_path / "image.vtu")
    r = simulate(read_mesh(tmp_path / "image.vtu"), {1: 1.0, 2: 3.0}, axes="x")
    assert r.k_eff["x"] == pytest.approx(1.5, rel=1e-8)
