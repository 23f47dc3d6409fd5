"""Our streaming .vtu writer, read back by VTK (pyvista) and meshio."""

import meshio
import numpy as np
import pytest

from napari_swa_imesh.mesh.formats._vtu import write_vtu


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
    import napari_swa_imesh.mesh.formats._vtu as vtu
    from napari_swa_imesh.mesh.model._quality import signed_volumes

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

    from napari_swa_imesh.mesh.formats._vtu import write_vtu

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


def _file_types(path) -> dict:
    """The ``type`` each ``<DataArray Name=...>`` declares in the file's XML header."""
    import re

    head = path.read_bytes().split(b"<AppendedData", 1)[0].decode()
    return {name: kind for kind, name in re.findall(r'<DataArray type="(\w+)" Name="([^"]+)"',
                                                     head)}


@pytest.mark.parametrize("big", [False, True])
def test_64_bit_integers_are_int32_in_the_file_only_when_every_value_fits(tmp_path, big):
    """Labels and leaf ids in 4 bytes when they fit, Int64 from 2**31 on: same values."""
    pv = pytest.importorskip("pyvista")
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]] * 40000)    # more than one chunk
    label = 2**31 if big else 2**31 - 1
    material = np.tile(np.array([-2**31, label], dtype=np.int64), 40000)
    leaf = np.arange(len(cells), dtype=np.int64)
    hits = np.arange(len(points), dtype=np.uint64)
    path = tmp_path / "m.vtu"
    write_vtu(path, points, cells, cell_data={"material": material, "leaf": leaf,
                                              "quality": np.full(len(cells), 5**0.5 / 2)},
              point_data={"hits": hits})
    assert _file_types(path) == {"material": "Int64" if big else "Int32", "leaf": "Int32",
                                 "quality": "Float64", "hits": "Int32",
                                 "connectivity": "Int32", "offsets": "Int32", "types": "UInt8"}
    grid, m = pv.read(path), meshio.read(path)
    for read in (grid.cell_data, {k: v[0] for k, v in m.cell_data.items()}):
        np.testing.assert_array_equal(read["material"], material)
        np.testing.assert_array_equal(read["leaf"], leaf)
        # the worst quality read back is still at (not above) its bound sqrt(5)/2
        assert (read["quality"] == 5**0.5 / 2).all()
    np.testing.assert_array_equal(grid.point_data["hits"], hits)


@pytest.mark.parametrize("label", [7, 2**40])
def test_read_mesh_gets_the_labels_and_leaves_of_a_meshed_volume_back(tmp_path, label):
    """write_mesh .vtu -> read_mesh (what ``swa-imesh simulate mesh.vtu`` reads): the
    materials, leaves and qualities of the mesher, whatever width the file gave them."""
    from napari_swa_imesh.mesh import mesh_labels, read_mesh, write_mesh

    labels = np.ones((4, 5, 6), dtype=np.int64)
    labels[1:3, 2:, 3:] = label
    mesh = mesh_labels(labels)
    path = write_mesh(mesh, tmp_path / "m.vtu")[0]
    assert _file_types(path)["material"] == ("Int32" if label < 2**31 else "Int64")
    back = read_mesh(path)
    assert back.material.dtype == np.int64
    assert set(np.unique(back.material)) == {1, label}
    # same element order in the file: compare per element
    np.testing.assert_array_equal(back.material, mesh.material)
    for key in ("leaf", "level", "quality", "min_dihedral", "max_dihedral"):
        np.testing.assert_array_equal(back.cell_data[key], mesh.cell_data[key], err_msg=key)
