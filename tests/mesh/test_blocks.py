"""Block-wise meshing (issue 27): the pieces assemble into the in-memory mesh exactly,
a misaligned block is caught by the seam check, the files are read by pyvista/meshio."""

from __future__ import annotations

import numpy as np
import pytest
from block_cases import balanced_grids, misalign_block
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_swa_imesh import build_tree
from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import facet_groups, mesh_labels, mesh_tree, read_mesh
from napari_swa_imesh.mesh.blocks import (
    BlockMeshError,
    mesh_blocks,
    read_pvtu_groups,
)
from napari_swa_imesh.mesh.blocks import _core as bk


def _volume(shape=(20, 24, 28), seed=1):
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.int64)
    s = tuple(slice(n // 6, n - n // 5) for n in shape)
    lab[s] = 1
    lab[(slice(shape[0] // 3, None), slice(shape[1] // 3, shape[1] // 2))] = 2
    lab[rng.random(shape) < 0.01] = 3
    return lab


def _pieces(lab, block, exclude=(0,), local_balance_at=None):
    """Every block's piece, in memory (the tasks' functions, no files). With
    `local_balance_at`, that block is meshed from its own region tree only (the coarse
    balance across its faces skipped): a deliberately misaligned block."""
    plan, mixed, split, present = balanced_grids(lab, block, exclude)
    pieces = []
    for idx in plan.blocks():
        grids = split
        if idx == local_balance_at:
            grids = bk.balance_grids(plan, {i: (m if i == idx else [np.zeros_like(g) for g in m])
                                            for i, m in mixed.items()})
        sl, _ = plan.window(idx)
        pieces.append(bk.mesh_block(plan, idx, lab[sl], bk.block_slices(plan, grids, idx),
                                    exclude=exclude, present=present))
    return plan, pieces


def _cell_keys(points, cells):
    """Elements as sorted rows of their corners' integer coordinates, rows sorted."""
    pts = np.round(points).astype(np.int64)
    flat = pts @ (np.int64(1 << 20) ** np.arange(pts.shape[1] - 1, -1, -1))
    keys = np.sort(flat[cells], axis=1)
    return keys[np.lexsort(keys.T[::-1])]


def _group_keys(points, facets):
    return _cell_keys(points, facets)


def _reference(lab, block, exclude=(0,)):
    """The in-memory mesh of the tree whose roots are the blocks (mesh_labels's own tree
    when the block is its root)."""
    top = int(block).bit_length() - 1
    if 1 << bk.default_top(lab.shape) <= block:
        return mesh_labels(lab, exclude=exclude)
    return mesh_tree(build_tree(lab, top_level=top), exclude=exclude)


def _assert_same(lab, block, exclude=(0,)):
    plan, pieces = _pieces(lab, block, exclude)
    assert all(not p.problems for p in pieces)
    assert bk.seam_mismatches(plan, {p.index: p.seams for p in pieces}) == []
    points, cells, material, quality, groups = bk.assemble(pieces, plan)
    ref = _reference(lab, plan.block, exclude)
    ref_pts = np.round(ref.points).astype(np.int64)
    assert np.array_equal(np.unique(np.round(points).astype(np.int64), axis=0),
                          np.unique(ref_pts, axis=0))
    assert len(points) == len(ref.points)
    assert np.array_equal(_cell_keys(points, cells), _cell_keys(ref.points, ref.cells))
    # materials and quality follow the elements
    order_b = np.lexsort(np.sort(_flat(points)[cells], axis=1).T[::-1])
    order_r = np.lexsort(np.sort(_flat(ref.points)[ref.cells], axis=1).T[::-1])
    assert np.array_equal(material[order_b], ref.material[order_r])
    assert np.allclose(quality[order_b], ref.quality[order_r])
    ref_groups = facet_groups(ref)
    assert sorted(groups) == sorted(ref_groups)
    for name, g in ref_groups.items():
        assert np.array_equal(_group_keys(points, groups[name][0]),
                              _group_keys(ref.points, g.facets)), name
        # owners are the same elements: the owner's material matches the group's side
        assert np.array_equal(np.sort(material[groups[name][1]]),
                              np.sort(ref.material[g.owner])), name
    return plan


def _flat(points):
    pts = np.round(points).astype(np.int64)
    return pts @ (np.int64(1 << 20) ** np.arange(pts.shape[1] - 1, -1, -1))


@pytest.mark.parametrize("block", [2, 4, 8, 16, 32])
def test_assembled_pieces_equal_the_in_memory_mesh_3d(block):
    plan = _assert_same(_volume(), block)
    assert plan.block == min(block, 16)           # 16: mesh_labels's root for 20 x 24 x 28


@pytest.mark.parametrize("block", [4, 8, 32])
def test_assembled_pieces_equal_the_in_memory_mesh_2d(block):
    _assert_same(_volume((27, 40), seed=3), block, exclude=())


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**16), block=st.sampled_from([2, 4, 8]),
       shape=st.tuples(st.integers(5, 19), st.integers(5, 19), st.integers(5, 19)),
       density=st.sampled_from([0.02, 0.2]))
def test_random_volumes_assemble_exactly(seed, block, shape, density):
    rng = np.random.default_rng(seed)
    lab = (rng.random(shape) < density).astype(np.int64) * rng.integers(1, 4, shape)
    if not (lab != 0).any():
        lab[0, 0, 0] = 1
    _assert_same(lab, block)


def test_a_block_balanced_alone_fails_the_seam_check():
    lab = _volume()
    plan, pieces = _pieces(lab, 4)
    assert bk.seam_mismatches(plan, {p.index: p.seams for p in pieces}) == []
    plan, pieces = _pieces(lab, 4, local_balance_at=(1, 2, 3))
    bad = bk.seam_mismatches(plan, {p.index: p.seams for p in pieces})
    assert bad and all("(1, 2, 3)" in b for b in bad)


def test_a_misaligned_block_leaves_nothing(tmp_path, monkeypatch):
    lab = _volume()
    misalign_block(monkeypatch, (0, 1, 1))
    with pytest.raises(BlockMeshError, match="disagree on their shared face"):
        mesh_blocks(lab, tmp_path / "m.pvtu", block=8, workers=0, exclude=(0,))
    assert list(tmp_path.iterdir()) == []


def test_files_read_back_as_the_same_mesh(tmp_path):
    pv = pytest.importorskip("pyvista")
    lab = _volume()
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=8, workers=0, exclude=(0,))
    ref = mesh_labels(lab, exclude=(0,))
    assert report["n_elements"] == ref.n_cells and report["equals_in_memory"] is False
    assert report["pieces"] == len(list((tmp_path / "m").glob("m_*_facets.vtu")))
    grid = pv.read(tmp_path / "m.pvtu")               # VTK's own .pvtu reader
    assert grid.n_cells == ref.n_cells
    assert {"material", "quality", "level"} <= set(grid.cell_data)
    assert "global_id" in grid.point_data
    assert grid.volume == pytest.approx(np.count_nonzero(lab))
    m = read_mesh(tmp_path / "m.pvtu")                # meshio per piece, joined by id
    assert m.n_cells == ref.n_cells and len(m.points) == len(ref.points)
    assert np.array_equal(_cell_keys(m.points, m.cells), _cell_keys(ref.points, ref.cells))
    groups = read_pvtu_groups(tmp_path / "m.pvtu")
    ref_groups = facet_groups(ref)
    assert sorted(groups) == sorted(ref_groups)
    shape1 = np.array(lab.shape) + 1
    for name, g in ref_groups.items():
        coords = np.round(ref.points[g.facets]).astype(np.int64)      # (F, 3, 3)
        ids = np.sort(np.ravel_multi_index(tuple(coords.transpose(2, 0, 1)), shape1), axis=1)
        assert np.array_equal(ids[np.lexsort(ids.T[::-1])],
                              groups[name][np.lexsort(groups[name].T[::-1])]), name


def test_simulate_reads_the_partitioned_mesh(tmp_path):
    from napari_swa_imesh.simulate import simulate

    lab = np.ones((12, 10, 14), np.int64)
    lab[:, :, 7:] = 2
    lab[4:8, 3:6, 2:5] = 3
    mesh_blocks(lab, tmp_path / "m.pvtu", block=8, workers=0)   # 8: mesh_labels's root
    k = {1: 1.0, 2: 10.0, 3: 5.0}
    blocks = simulate(read_mesh(tmp_path / "m.pvtu"), k, order=1)
    whole = simulate(mesh_labels(lab), k, order=1)
    assert blocks.dofs == whole.dofs
    for axis, value in whole.k_eff.items():
        assert blocks.k_eff[axis] == pytest.approx(value, rel=1e-9)


def test_xdmf_pieces_match_their_index(tmp_path):
    import xml.etree.ElementTree as ET

    h5py = pytest.importorskip("h5py")
    lab = _volume()
    report = mesh_blocks(lab, tmp_path / "m.xdmf", block=8, workers=0, exclude=(0,))
    grids = ET.parse(tmp_path / "m.xdmf").getroot().findall("./Domain/Grid/Grid")
    assert len(grids) == report["pieces"]
    total = 0
    for grid in grids:
        for item in grid.iter("DataItem"):
            file, name = item.text.split(":")
            with h5py.File(tmp_path / file) as h5:
                assert h5[name].shape == tuple(int(x) for x in item.attrib["Dimensions"].split())
        total += int(grid.find("Topology").attrib["NumberOfElements"])
    assert total == report["n_elements"] == mesh_labels(lab, exclude=(0,)).n_cells


def test_a_failed_block_is_retried(tmp_path, monkeypatch):
    real, failed = bk.mesh_block, []

    def flaky(plan, index, *args, **kw):
        if index == (1, 1, 1) and not failed:
            failed.append(index)
            raise OSError("lost the worker's disk for a moment")
        return real(plan, index, *args, **kw)

    monkeypatch.setattr(bk, "mesh_block", flaky)
    lab = _volume()
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=8, workers=0, exclude=(0,))
    assert failed and report["n_elements"] == mesh_labels(lab, exclude=(0,)).n_cells


def test_on_a_dask_client(tmp_path):
    distributed = pytest.importorskip("distributed")
    lab = _volume()
    np.save(tmp_path / "l.npy", lab)
    ref = mesh_labels(lab, exclude=(0,)).n_cells
    with distributed.LocalCluster(processes=False, n_workers=1, threads_per_worker=2,
                                  dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            report = mesh_blocks(tmp_path / "l.npy", tmp_path / "m.pvtu", block=8,
                                 client=client, exclude=(0,))
        assert report["n_elements"] == ref
        # the same through the scheduler's address (as --scheduler gives it)
        report = mesh_blocks(tmp_path / "l.npy", tmp_path / "s.pvtu", block=8,
                             scheduler=cluster.scheduler_address, exclude=(0,))
        assert report["n_elements"] == ref


def test_command_line(tmp_path, capsys):
    lab = _volume()
    np.save(tmp_path / "l.npy", lab.astype(np.uint8))
    out = tmp_path / "m.pvtu"
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(out), "--workers", "0",
                 "--exclude", "0", "--block", "8"]) == 0
    assert "seams conforming; volumes exact" in capsys.readouterr().out
    assert read_mesh(out).n_cells == mesh_labels(lab, exclude=(0,)).n_cells
    # refused before any work, one sentence, nothing written
    code = main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "n.pvtu"),
                 "--method", "delaunay"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--method is not available" in err
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(out), "--workers", "0"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(out), "--workers", "0",
                 "--force", "--exclude", "0"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy", "m", "m.pvtu"]
    # a user's folder of that name is never replaced, even with --force
    (tmp_path / "u").mkdir()
    (tmp_path / "u" / "notes.txt").write_text("mine")
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "u.pvtu"),
                 "--workers", "0", "--force"]) == 2
    assert "not pieces of u.pvtu" in capsys.readouterr().err
    assert (tmp_path / "u" / "notes.txt").read_text() == "mine"


def test_the_block_side_follows_the_memory_per_worker():
    from napari_swa_imesh.mesh.blocks import block_memory, choose_block

    assert choose_block((256,) * 3, 4 << 30) == 128         # 256 would need ~27 GB
    assert block_memory(128) <= 4 << 30 < block_memory(256)
    assert choose_block((20, 24, 28), None) == 16           # never above mesh's root
    with pytest.raises(ValueError, match="give more --memory"):
        choose_block((256,) * 3, 1 << 20)
    with pytest.raises(ValueError, match="above --memory"):
        choose_block((256,) * 3, 1 << 30, block=256)
    with pytest.raises(ValueError, match="power of two"):
        bk.plan_blocks((20, 24, 28), 12)
