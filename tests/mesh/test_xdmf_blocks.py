"""XDMF written block by block equals meshio's XDMF writer, read back by meshio."""

import importlib.util

import meshio
import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels, write_mesh
from napari_swa_imesh.mesh.formats import _xdmf
from napari_swa_imesh.mesh.formats._export import _meshio_of
from napari_swa_imesh.mesh.formats._prepare import ExportMesh

pytestmark = pytest.mark.skipif(importlib.util.find_spec("h5py") is None,
                                reason="XDMF needs h5py, not installed")


def _labels(ndim):
    rng = np.random.default_rng(ndim)
    shape = (9, 11) if ndim == 2 else (5, 6, 7)
    return rng.integers(1, 4, size=shape).astype(np.uint8)


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("order", [1, 2])
def test_blocks_read_back_equal_to_meshios_writer(tmp_path, monkeypatch, ndim, order):
    mesh = mesh_labels(_labels(ndim), spacing=(0.5,) * ndim)
    mesh.cell_data["flag"] = np.arange(mesh.n_cells) % 3 == 0          # bool: widened
    ex = ExportMesh(mesh, order=order, groups="none")
    meshio.write(tmp_path / "old.xdmf", _meshio_of(ex), file_format="xdmf")
    monkeypatch.setattr(_xdmf, "BLOCK", 7)          # many blocks, a short last one
    write_mesh(mesh, tmp_path / "new.xdmf", order=order, facet_groups="none")
    old, new = meshio.read(tmp_path / "old.xdmf"), meshio.read(tmp_path / "new.xdmf")
    assert mesh.n_cells > 7 * 10
    np.testing.assert_array_equal(new.points, old.points)
    assert [c.type for c in new.cells] == [c.type for c in old.cells]
    np.testing.assert_array_equal(new.cells[0].data, old.cells[0].data)
    assert new.cells[0].data.dtype == old.cells[0].data.dtype
    assert sorted(new.cell_data) == sorted(old.cell_data)
    assert {"flag", "material", "quality"} <= set(new.cell_data)
    for key, (values,) in old.cell_data.items():
        assert new.cell_data[key][0].dtype == values.dtype
        np.testing.assert_array_equal(new.cell_data[key][0], values)


def test_h5_holds_the_mesh_once_under_meshios_names(tmp_path):
    import h5py

    mesh = mesh_labels(_labels(3))
    write_mesh(mesh, tmp_path / "m.xdmf", facet_groups="none")
    with h5py.File(tmp_path / "m.h5", "r") as h5:
        assert sorted(h5) == sorted(f"data{k}" for k in range(3 + len(mesh.cell_data)))
        assert (h5["data1"].shape == (mesh.n_cells, 4) and h5["data1"].compression == "gzip"
                and h5["data1"].shuffle)
    assert "m.h5:/data1" in (tmp_path / "m.xdmf").read_text()
