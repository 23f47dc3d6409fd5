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
