"""Our streaming .vtu writer, read back by VTK (pyvista) and meshio."""

import meshio
import numpy as np
import pytest

from napari_swa_imesh.mesh._vtu import write_vtu


@pytest.mark.parametrize("ndim", [2, 3])
def test_vtk_and_meshio_read_every_array_with_its_dtype(tmp_path, ndim):
    pv = pytest.importorskip("pyvista")
    rng = np.random.default_rng(ndim)
    points = rng.random((7, ndim))
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5]])[:, : ndim + 1]
    cell_data = {"material": np.array([1, 2, 3], dtype=np.int64),
                 "level": np.array([0, 1, 2], dtype=np.int8),
                 "flag": np.array([True, False, True]),
                 "flux": rng.random((3, 3))}
    point_data = {"u": rng.random(7).astype(np.float32)}
    path = tmp_path / "m.vtu"
    write_vtu(path, points, cells, cell_data=cell_data, point_data=point_data)
    grid = pv.read(path)
    assert grid.n_cells == 3 and grid.n_points == 7
    np.testing.assert_array_equal(grid.points[:, :ndim], points)
    np.testing.assert_array_equal(grid.cell_data["level"], cell_data["level"])
    assert grid.cell_data["level"].dtype == np.int8
    np.testing.assert_array_equal(grid.cell_data["flux"], cell_data["flux"])
    np.testing.assert_array_equal(grid.point_data["u"], point_data["u"])
    m = meshio.read(path)
    np.testing.assert_array_equal(m.cells[0].data, cells)
    np.testing.assert_array_equal(m.cell_data["material"][0], cell_data["material"])
    np.testing.assert_array_equal(m.cell_data["flag"][0], [1, 0, 1])
    assert m.cell_data["flux"][0].shape == (3, 3)


def test_slices_join_into_one_base64_stream(tmp_path, monkeypatch):
    """An array longer than one slice reads back whole (slices of 3k bytes join)."""
    import napari_swa_imesh.mesh._vtu as vtu

    monkeypatch.setattr(vtu, "_SLICE", 3 * 5)        # 15-byte slices: many per array
    points = np.random.default_rng(0).random((40, 3))
    cells = np.arange(40).reshape(10, 4)
    write_vtu(tmp_path / "s.vtu", points, cells, cell_data={"q": np.arange(10.0)})
    m = meshio.read(tmp_path / "s.vtu")
    np.testing.assert_array_equal(m.points, points)
    np.testing.assert_array_equal(m.cell_data["q"][0], np.arange(10.0))
