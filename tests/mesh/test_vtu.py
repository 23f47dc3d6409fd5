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


@pytest.mark.parametrize("ndim", [2, 3])
def test_chunks_join_and_orientation_is_fixed_chunk_by_chunk(tmp_path, monkeypatch, ndim):
    """Connectivity, offsets and types written in many chunks read back whole; with
    orient=True every cell comes back positively oriented, the input untouched."""
    import napari_swa_imesh.mesh._vtu as vtu
    from napari_swa_imesh.mesh._quality import signed_volumes

    pv = pytest.importorskip("pyvista")
    monkeypatch.setattr(vtu, "_CHUNK", 3)
    rng = np.random.default_rng(ndim)
    points = rng.random((30, ndim))
    cells = np.array([rng.choice(30, ndim + 1, replace=False) for _ in range(20)])
    before = cells.copy()
    write_vtu(tmp_path / "c.vtu", points, cells, cell_data={"q": np.arange(20.0)}, orient=True)
    np.testing.assert_array_equal(cells, before)
    assert b'encoding="raw"' in (tmp_path / "c.vtu").read_bytes()[:2000]
    m = meshio.read(tmp_path / "c.vtu")
    back = m.cells[0].data
    assert (signed_volumes(points, back) > 0).all()
    np.testing.assert_array_equal(np.sort(back, axis=1), np.sort(cells, axis=1))
    np.testing.assert_array_equal(m.cell_data["q"][0], np.arange(20.0))
    grid = pv.read(tmp_path / "c.vtu")
    assert grid.n_cells == 20 and (grid.celltypes == (5 if ndim == 2 else 10)).all()
    np.testing.assert_array_equal(grid.cells_dict[5 if ndim == 2 else 10], back)


def test_meshio_reads_every_array_whatever_the_block_sizes(tmp_path):
    # meshio converts raw appended data to base64 looking tags up by old offsets; a new
    # offset equal to a later block's old one made it read the wrong block (a 2-D mesh of
    # 36 triangles with Int8 and Float64 arrays did): every size from 1 to 40 cells
    import meshio

    from napari_swa_imesh.mesh._vtu import write_vtu

    rng = np.random.default_rng(0)
    for n in range(1, 41):
        points = rng.random((n + 2, 2))
        cells = np.stack([np.arange(n), np.arange(n) + 1, np.arange(n) + 2], axis=1)
        data = {"a": rng.integers(0, 9, n).astype(np.int8), "b": rng.random(n),
                "c": rng.integers(0, 9, n).astype(np.int64), "d": rng.random(n),
                "e": rng.integers(0, 9, n).astype(np.int8), "f": rng.random((n, 3))}
        write_vtu(tmp_path / "m.vtu", points, cells, cell_data=data,
                  point_data={"p": rng.random(n + 2)})
        back = meshio.read(tmp_path / "m.vtu")
        np.testing.assert_array_equal(back.cells[0].data, cells)
        np.testing.assert_allclose(back.points[:, :2], points)
        for key, values in data.items():
            np.testing.assert_array_equal(back.cell_data[key][0], values, err_msg=(n, key))
