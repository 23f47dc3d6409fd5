"""Block-wise meshing at order 2 and with periodic faces (issue 27): the assembled
pieces equal the in-memory mesh for several block sizes, and a misaligned block fails
the check that covers it (seams across block faces, the box faces across the box)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from block_cases import balanced_grids, boxed, misalign_block
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_swa_imesh import build_tree
from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import facet_groups, mesh_labels, read_mesh, write_mesh
from napari_swa_imesh.mesh.blocks import BlockMeshError, _periodic, mesh_blocks, read_pvtu_groups
from napari_swa_imesh.mesh.blocks import _core as bk
from napari_swa_imesh.mesh.formats._order2 import EDGE_ORDER
from napari_swa_imesh.mesh.mesher._imesh import _mesh_tree
from napari_swa_imesh.mesh.mesher._lattice import split_box_faces

meshio = pytest.importorskip("meshio")


def _volume(shape=(13, 10, 12)):
    return boxed(shape, seed=2, p=0.04)


def _keys(points, rows):
    """Rows of nodes as sorted rows of their (doubled, integer) coordinates, rows sorted."""
    pts = np.rint(2 * np.asarray(points)).astype(np.int64)
    flat = pts @ (np.int64(1 << 20) ** np.arange(pts.shape[1] - 1, -1, -1))
    keys = np.sort(flat[rows], axis=1)
    return keys[np.lexsort(keys.T[::-1])]


# --------------------------------------------------------------------------- periodic
def _pieces(lab, block, exclude=(0,), wrong_rule_at=None):
    """Every block's piece (the tasks' functions, no files) of a periodic plan; with
    `wrong_rule_at`, that block cuts its faces by the non-periodic diagonal rule."""
    plan, _, split, present = balanced_grids(lab, block, exclude, periodic=True)
    pieces = []
    for idx in plan.blocks():
        sl, _ = plan.window(idx)
        p = dataclasses.replace(plan, periodic=False) if idx == wrong_rule_at else plan
        pieces.append(bk.mesh_block(p, idx, lab[sl], bk.block_slices(plan, split, idx),
                                    exclude=exclude, present=present))
    return plan, pieces


def _periodic_reference(lab, block, exclude):
    d = lab.ndim
    if 1 << bk.default_top(lab.shape) <= block:
        return mesh_labels(lab, exclude=exclude, periodic=True)
    tree = split_box_faces(build_tree(lab, top_level=int(block).bit_length() - 1))
    return _mesh_tree(tree, method="template", exclude=np.asarray(exclude, np.int64),
                      spacing=(1.0,) * d, material_names={}, connectivity=None,
                      report_face_balance=False, seconds={}, periodic=True)


@pytest.mark.parametrize(("shape", "block", "exclude"), [
    ((13, 10, 12), 2, (0,)), ((13, 10, 12), 4, (0,)), ((13, 10, 12), 8, ()),
    ((12, 10, 14), 4, (0,)), ((17, 22), 4, (0,)), ((17, 22), 16, ())])
def test_periodic_pieces_assemble_into_the_in_memory_mesh(shape, block, exclude):
    _assert_periodic_same(_volume(shape), block, exclude)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**16), block=st.sampled_from([2, 4, 8]),
       shape=st.tuples(st.integers(3, 13), st.integers(3, 13), st.integers(3, 13)))
def test_random_periodic_volumes_assemble_exactly(seed, block, shape):
    rng = np.random.default_rng(seed)
    lab = rng.integers(0, 3, shape) * (rng.random(shape) < 0.3)
    lab[0, 0, 0] = 1
    _assert_periodic_same(lab, block, (0,))


@pytest.mark.parametrize("options", [{"order": 2}, {"periodic": True}, {"refine": 1},
                                     {"coarsen": 1}])
@pytest.mark.filterwarnings("ignore:coarsening by")
def test_a_misaligned_block_still_fails_the_seam_check(tmp_path, monkeypatch, options):
    lab = _volume()
    misalign_block(monkeypatch, (1, 1, 1))
    with pytest.raises(BlockMeshError, match="disagree on their shared face"):
        mesh_blocks(lab, tmp_path / "m.pvtu", block=4, workers=0, exclude=(0,), **options)
    assert list(tmp_path.iterdir()) == []


def _assert_periodic_same(lab, block, exclude):
    shape = lab.shape
    plan, pieces = _pieces(lab, block, exclude)
    assert all(not p.problems for p in pieces)
    assert bk.seam_mismatches(plan, {p.index: p.seams for p in pieces}) == []
    boxes = {p.index: _periodic.box_facets(p, plan.shape) for p in pieces}
    assert _periodic.periodic_mismatches(plan, boxes) == []
    points, cells, material, _, groups = bk.assemble(pieces, plan)
    ref = _periodic_reference(lab, plan.block, exclude)
    assert len(points) == len(ref.points) and len(cells) == ref.n_cells
    assert np.array_equal(_keys(points, cells), _keys(ref.points, ref.cells))
    assert np.array_equal(np.unique(np.rint(points), axis=0),
                          np.unique(np.rint(ref.points), axis=0))
    ref_groups = facet_groups(ref)
    assert sorted(groups) == sorted(ref_groups)
    for name, g in ref_groups.items():
        assert np.array_equal(_keys(points, groups[name][0]),
                              _keys(ref.points, g.facets)), name
    # the box really is split to one lattice cell: every element touching it is level 0
    corners = np.rint(points[cells])                                      # (M, d+1, d)
    on_box = ((corners == 0) | (corners == np.array(shape))).any(axis=2).any(axis=1)
    assert on_box.any() and (np.ptp(corners, axis=1).max(axis=1)[on_box] == 1).all()


def test_a_block_cut_by_another_rule_fails_the_periodic_check():
    lab = _volume()                                    # odd extent: the "lowest" rule
    plan, pieces = _pieces(lab, 4, wrong_rule_at=(0, 0, 0))
    assert plan.rule == "lowest"
    boxes = {p.index: _periodic.box_facets(p, plan.shape) for p in pieces}
    bad = _periodic.periodic_mismatches(plan, boxes)
    assert len(bad) == 3 and all("box faces" in b for b in bad)  # it touches 3 low sides


def test_an_unmatched_box_face_leaves_nothing(tmp_path, monkeypatch):
    lab = _volume()
    real = _periodic.box_facets

    def shifted(piece, shape):
        out = real(piece, shape)
        if piece.index == (0, 1, 2):                 # its low z side one lattice key off
            out[(0, -1)] = out[(0, -1)] + 1
        return out

    monkeypatch.setattr(_periodic, "box_facets", shifted)
    with pytest.raises(BlockMeshError, match="box faces across axis 0 differ"):
        mesh_blocks(lab, tmp_path / "m.pvtu", block=4, workers=0, exclude=(0,),
                    periodic=True)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=4, workers=0, exclude=(0,),
                         periodic=True)
    assert report["periodic"] and report["n_elements"] == _periodic_reference(
        lab, 4, (0,)).n_cells


# --------------------------------------------------------------------------- order 2
def _read_pieces(folder):
    """The order-2 pieces joined by global id: (nodes (N, d), cells (M, k) in node rows)."""
    gids, pts, cells = [], [], []
    offset = 0
    for f in sorted(folder.glob("*.vtu")):
        if f.name.endswith("_facets.vtu"):
            continue
        m = meshio.read(f)
        assert [c.type for c in m.cells] in (["tetra10"], ["triangle6"])
        gids.append(np.asarray(m.point_data["global_id"]).astype(np.int64).ravel())
        pts.append(m.points)
        cells.append(m.cells[0].data + offset)
        offset += len(m.points)
    uniq, first, inverse = np.unique(np.concatenate(gids), return_index=True,
                                     return_inverse=True)
    return np.concatenate(pts)[first], inverse[np.concatenate(cells)]


def _mid_nodes_are_midpoints(points, cells, corners):
    pairs = np.array(EDGE_ORDER["vtk"][corners])
    mid = (points[cells[:, pairs[:, 0]]] + points[cells[:, pairs[:, 1]]]) / 2
    return np.array_equal(mid, points[cells[:, corners:]])


@pytest.mark.parametrize(("shape", "block", "exclude"), [
    ((13, 10, 12), 4, (0,)), ((13, 10, 12), 8, (0,)), ((13, 10, 12), 16, ()),
    ((17, 22), 4, (0,)), ((17, 22), 32, ())])
def test_order_2_pieces_equal_the_in_memory_order_2_mesh(tmp_path, shape, block, exclude):
    lab = _volume(shape)
    d = lab.ndim
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=block, workers=0, exclude=exclude,
                         order=2)
    assert report["order"] == 2
    nodes, cells = _read_pieces(tmp_path / "m")
    top = int(report["block"]).bit_length() - 1
    ref = (mesh_labels(lab, exclude=exclude) if report["equals_in_memory"] else
           _mesh_tree(build_tree(lab, top_level=top), method="template",
                      exclude=np.asarray(exclude, np.int64), spacing=(1.0,) * d,
                      material_names={}, connectivity=None, report_face_balance=False,
                      seconds={}))
    write_mesh(ref, tmp_path / "ref.vtu", order=2)
    rm = meshio.read(tmp_path / "ref.vtu")
    ref_nodes, ref_cells = rm.points[:, :d], rm.cells[0].data
    nodes = nodes[:, :d]
    # the same nodes (one per corner and per edge: none doubled across blocks) ...
    assert len(nodes) == len(ref_nodes)
    assert np.array_equal(np.unique(np.rint(2 * nodes), axis=0),
                          np.unique(np.rint(2 * ref_nodes), axis=0))
    # ... the same elements (corners up to order), each mid-edge node on its edge
    assert cells.shape == ref_cells.shape
    assert np.array_equal(_keys(nodes, cells[:, :d + 1]), _keys(ref_nodes, ref_cells[:, :d + 1]))
    assert _mid_nodes_are_midpoints(nodes, cells, d + 1)
    assert _mid_nodes_are_midpoints(ref_nodes, ref_cells, d + 1)
    # the same groups, of second order in the companions
    groups = read_pvtu_groups(tmp_path / "m.pvtu")
    ref_groups = facet_groups(ref)
    assert sorted(groups) == sorted(ref_groups)
    for comp in (tmp_path / "m").glob("*_facets.vtu"):
        if b'NumberOfCells="0"' in comp.read_bytes()[:4000]:
            continue                                 # meshio cannot read an empty grid
        c = meshio.read(comp)
        assert [b.type for b in c.cells] == ["triangle6" if d == 3 else "line3"]
        assert _mid_nodes_are_midpoints(c.points, c.cells[0].data, d)
    # read_mesh gives the linear mesh, as for any second-order file
    lin = read_mesh(tmp_path / "m.pvtu")
    assert lin.n_cells == ref.n_cells and len(lin.points) == len(ref.points)


def test_order_2_xdmf_pieces(tmp_path):
    h5py = pytest.importorskip("h5py")
    lab = _volume()
    report = mesh_blocks(lab, tmp_path / "m.xdmf", block=4, workers=0, exclude=(0,),
                         order=2)
    ref = mesh_labels(lab, exclude=(0,))
    total = 0
    for piece in sorted((tmp_path / "m").glob("*.xdmf")):
        m = meshio.read(piece)
        assert m.cells[0].type == "tetra10"
        with h5py.File(piece.with_suffix(".h5")) as h5:
            assert h5["points"].shape[0] == len(m.points)
            assert all(h5[f"facets/{n}"].shape[1] == 6 for n in h5["facets"])
        total += len(m.cells[0].data)
    assert total == report["n_elements"] == ref.n_cells
    assert read_mesh(tmp_path / "m.xdmf").n_cells == ref.n_cells


def test_command_line_order_2_and_periodic(tmp_path, capsys):
    lab = _volume()
    np.save(tmp_path / "l.npy", lab.astype(np.uint8))
    for option, check in ((["--order", "2"], lambda m: m.n_cells == mesh_labels(
            lab, exclude=(0,)).n_cells),
                          (["--periodic"], lambda m: m.n_cells == mesh_labels(
            lab, exclude=(0,), periodic=True).n_cells)):
        out = tmp_path / f"m{option[0][2:]}.pvtu"
        assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(out), "--workers", "0",
                     "--exclude", "0"] + option) == 0
        said = capsys.readouterr().out
        assert "seams conforming" in said
        assert ("10-node elements" in said) == (option[0] == "--order")
        assert ("box faces periodic" in said) == (option[0] == "--periodic")
        assert check(read_mesh(out))
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "x.pvtu"),
                 "--workers", "0", "--order", "3"]) == 2
    assert "--order must be 1 or 2" in capsys.readouterr().err
