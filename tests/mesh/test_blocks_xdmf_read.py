"""The XDMF output of block-wise meshing (issue 27) is read by the readers that read it:
VTK's XdmfReader (ParaView) the spatial collection, meshio each piece's own one-grid
file, read_mesh / read_pvtu_groups the whole, joined by global ids."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from napari_swa_imesh.mesh import facet_groups, mesh_labels, read_mesh
from napari_swa_imesh.mesh.blocks import is_xdmf_index, mesh_blocks, read_pvtu_groups

pytestmark = pytest.mark.skipif(importlib.util.find_spec("h5py") is None,
                                reason="XDMF needs h5py, not installed")


def _volume(shape):
    rng = np.random.default_rng(5)
    lab = np.zeros(shape, np.int64)
    lab[tuple(slice(2, n - 2) for n in shape)] = 1
    lab[(slice(shape[0] // 2, None),) + (slice(None),) * (len(shape) - 1)] *= 2
    lab[rng.random(shape) < 0.03] = 3
    return lab


def _keys(points, cells):
    pts = np.rint(points).astype(np.int64)
    flat = pts @ (np.int64(1 << 20) ** np.arange(pts.shape[1] - 1, -1, -1))
    keys = np.sort(flat[cells], axis=1)
    return keys[np.lexsort(keys.T[::-1])]


@pytest.mark.parametrize("shape", [(14, 17, 12), (21, 30)])
def test_read_mesh_joins_the_xdmf_pieces(tmp_path, shape):
    import meshio

    lab = _volume(shape)
    report = mesh_blocks(lab, tmp_path / "m.xdmf", block=4, workers=0, exclude=(0,))
    ref = mesh_labels(lab, exclude=(0,))
    assert is_xdmf_index(tmp_path / "m.xdmf")
    pieces = sorted((tmp_path / "m").glob("m_*.xdmf"))
    assert len(pieces) == report["pieces"] > 1
    # meshio reads every piece's own file (it takes one grid per file)
    assert sum(len(meshio.read(p).cells[0].data) for p in pieces) == ref.n_cells
    whole = read_mesh(tmp_path / "m.xdmf")
    assert whole.n_cells == ref.n_cells and len(whole.points) == len(ref.points)
    assert whole.info["pieces"] == report["pieces"]
    assert np.array_equal(_keys(whole.points, whole.cells), _keys(ref.points, ref.cells))
    assert sorted(read_pvtu_groups(tmp_path / "m.xdmf")) == sorted(facet_groups(ref))


def test_vtks_xdmf_reader_reads_the_collection(tmp_path):
    vtk = pytest.importorskip("vtk")
    if not hasattr(vtk, "vtkXdmfReader"):
        pytest.skip("this VTK has no XdmfReader")
    lab = _volume((14, 17, 12))
    report = mesh_blocks(lab, tmp_path / "m.xdmf", block=8, workers=0, exclude=(0,))
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(tmp_path / "m.xdmf"))
    reader.Update()
    out = reader.GetOutputDataObject(0)
    it = out.NewIterator()
    it.InitTraversal()
    n_blocks = n_cells = 0
    while not it.IsDoneWithTraversal():
        block = it.GetCurrentDataObject()
        assert block.GetCellData().GetArray("material") is not None
        assert block.GetPointData().GetArray("global_id") is not None
        n_blocks += 1
        n_cells += block.GetNumberOfCells()
        it.GoToNextItem()
    assert n_blocks == report["pieces"] and n_cells == report["n_elements"]


def test_an_in_memory_xdmf_is_not_taken_for_an_index(tmp_path):
    from napari_swa_imesh.mesh import write_mesh

    mesh = mesh_labels(_volume((6, 7, 5)))
    write_mesh(mesh, tmp_path / "one.xdmf", facet_groups="none")
    assert not is_xdmf_index(tmp_path / "one.xdmf")
    assert read_mesh(tmp_path / "one.xdmf").n_cells == mesh.n_cells
