"""Block-wise interface refinement and coarsening (issue 27): the pieces of
``refine=K`` / ``coarsen=C`` assemble into the in-memory mesh for several block sizes
(vertices, elements, groups)."""

from __future__ import annotations

import numpy as np
import pytest
from block_cases import boxed

from napari_swa_imesh import build_tree
from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import facet_groups, mesh_labels, read_mesh
from napari_swa_imesh.mesh.blocks import _core as bk
from napari_swa_imesh.mesh.blocks import mesh_blocks, read_pvtu_groups
from napari_swa_imesh.mesh.mesher._imesh import _mesh_tree
from napari_swa_imesh.mesh.mesher._lattice import _InterfaceFaces, split_leaves


def _volume(shape):
    return boxed(shape, seed=4, p=0.03)


def _reference(lab, k, block, exclude):
    """The in-memory refined mesh of the tree whose roots are blocks of `block` cells."""
    if 1 << bk.default_top(tuple(n << k for n in lab.shape)) <= block:
        return mesh_labels(lab, refine=k, exclude=exclude)
    fine = lab
    for a in range(lab.ndim):
        fine = np.repeat(fine, 1 << k, axis=a)
    tree = build_tree(fine, top_level=int(block).bit_length() - 1)
    faces = _InterfaceFaces(lab, np.asarray(exclude, np.int64))
    cells = np.full(lab.ndim, 1 << k, np.int64)
    tree = split_leaves(tree, lambda origin, size: faces.touches(origin, size, cells))
    return _mesh_tree(tree, method="template", exclude=np.asarray(exclude, np.int64),
                      spacing=(1.0,) * lab.ndim, material_names={}, connectivity=None,
                      report_face_balance=False, seconds={})


def _keys(points, rows, scale):
    pts = np.rint(scale * np.asarray(points)).astype(np.int64)
    flat = pts @ (np.int64(1 << 20) ** np.arange(pts.shape[1] - 1, -1, -1))
    keys = np.sort(flat[rows], axis=1)
    return keys[np.lexsort(keys.T[::-1])]


@pytest.mark.parametrize(("shape", "k", "block", "exclude"), [
    ((9, 7, 8), 1, 4, (0,)), ((9, 7, 8), 1, 16, ()), ((6, 5, 7), 2, 8, (0,)),
    ((13, 11), 1, 4, (0,)), ((13, 11), 2, 64, ())])
def test_refined_pieces_equal_the_in_memory_refined_mesh(tmp_path, shape, k, block, exclude):
    lab = _volume(shape)
    report = mesh_blocks(lab, tmp_path / "m.pvtu", block=block, workers=0, exclude=exclude,
                         refine=k)
    assert report["lattice"]["refine"] == k
    ref = (mesh_labels(lab, refine=k, exclude=exclude) if report["equals_in_memory"]
           else _reference(lab, k, report["block"], exclude))
    got = read_mesh(tmp_path / "m.pvtu")
    scale = 1 << k                                  # lattice units: integers
    ref_scale = scale if report["equals_in_memory"] else 1   # _mesh_tree's: lattice units
    assert got.n_cells == ref.n_cells and len(got.points) == len(ref.points)
    assert np.array_equal(_keys(got.points, got.cells, scale),
                          _keys(ref.points, ref.cells, ref_scale))
    # refinement really happened: elements at interfaces are one lattice cell
    assert ref.n_cells > mesh_labels(lab, exclude=exclude).n_cells
    groups = read_pvtu_groups(tmp_path / "m.pvtu")
    ref_groups = facet_groups(ref)
    assert sorted(groups) == sorted(ref_groups)
    shape1 = np.array([(n << k) + 1 for n in shape])
    for name, g in ref_groups.items():
        coords = np.rint(ref_scale * ref.points[g.facets]).astype(np.int64)  # (F, d, d)
        ids = np.sort(np.ravel_multi_index(tuple(np.moveaxis(coords, 2, 0)), shape1), axis=1)
        assert np.array_equal(ids[np.lexsort(ids.T[::-1])],
                              groups[name][np.lexsort(groups[name].T[::-1])]), name


@pytest.mark.filterwarnings("ignore:coarsening by")
def test_command_line_refine_and_coarsen(tmp_path, capsys):
    lab = _volume((9, 7, 8))
    np.save(tmp_path / "l.npy", lab.astype(np.uint8))
    out = tmp_path / "m.pvtu"
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(out), "--workers", "0",
                 "--exclude", "0", "--refine", "1"]) == 0
    assert "seams conforming" in capsys.readouterr().out
    assert read_mesh(out).n_cells == mesh_labels(lab, exclude=(0,), refine=1).n_cells
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "n.pvtu"),
                 "--workers", "0", "--refine", "9"]) == 2
    assert not (tmp_path / "n.pvtu").exists()
    capsys.readouterr()
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "c.pvtu"),
                 "--workers", "0", "--exclude", "0", "--coarsen", "1"]) == 0
    assert "seams conforming" in capsys.readouterr().out
    with pytest.warns(UserWarning):
        n_ref = mesh_labels(lab, exclude=(0,), coarsen=1).n_cells
    assert read_mesh(tmp_path / "c.pvtu").n_cells == n_ref


# --------------------------------------------------------------------------- coarsen
@pytest.mark.parametrize(("c", "block"), [(1, 4), (1, 16), (2, 4), (2, 8), (2, 16)])
def test_coarsened_pieces_equal_the_in_memory_coarsened_mesh(tmp_path, c, block):
    from napari_swa_imesh.mesh import mesh_tree
    from napari_swa_imesh.mesh.mesher._coarsen import coarsen_labels

    rng = np.random.default_rng(c)
    lab = np.ones((21, 18, 23), np.int64)
    lab[4:15, 6:13, 3:20] = 2
    lab[rng.random(lab.shape) < 0.05] = 3           # specks: voted away, as in memory
    lab[:6, :5, :7] = 4                             # a corner block that survives
    with pytest.warns(UserWarning, match=r"removed material\(s\) 3 entirely"):
        report = mesh_blocks(lab, tmp_path / "m.pvtu", block=block, workers=0,
                             exclude=(0,), coarsen=c)
    assert report["coarsen"] == {"level": c, "lost": [3]}
    coarse = coarsen_labels(lab, c)[0]
    if report["equals_in_memory"]:
        with pytest.warns(UserWarning):
            ref = mesh_labels(lab, exclude=(0,), coarsen=c)
    else:
        ref = mesh_tree(build_tree(coarse, top_level=block.bit_length() - 1), exclude=(0,))
    got = read_mesh(tmp_path / "m.pvtu")
    assert got.n_cells == ref.n_cells and len(got.points) == len(ref.points)
    assert np.array_equal(_keys(got.points, got.cells, 1), _keys(ref.points, ref.cells, 1))
    for m in (1, 2, 4):                             # volumes exact, of the voted labels
        assert report["volumes"][m] == np.count_nonzero(coarse == m)
    groups = read_pvtu_groups(tmp_path / "m.pvtu")
    assert {n: len(g) for n, g in groups.items()} == {
        n: len(g.facets) for n, g in facet_groups(ref).items()}


@pytest.mark.filterwarnings("ignore:coarsening by")
@pytest.mark.parametrize("options", [
    {"refine": 1, "periodic": True}, {"coarsen": 1, "refine": 1, "order": 2},
    {"periodic": True, "spacing": (2.0, 1.0, 1.0)},
    {"coarsen": 1, "periodic": True, "max_size": 3.0}])
def test_options_combine_as_in_memory(tmp_path, options):
    lab = _volume((13, 10, 12))
    report = mesh_blocks(lab, tmp_path / "m.pvtu", workers=0, exclude=(0,), **options)
    assert report["equals_in_memory"]
    ref = mesh_labels(lab, exclude=(0,), **{k: v for k, v in options.items() if k != "order"})
    got = read_mesh(tmp_path / "m.pvtu")
    assert got.n_cells == ref.n_cells and len(got.points) == len(ref.points)
    assert np.array_equal(_keys(got.points, got.cells, 2), _keys(ref.points, ref.cells, 2))


def test_coarsening_takes_whole_valued_float_labels_and_refuses_others(tmp_path):
    lab = np.ones((12, 10, 9))
    lab[3:8, 2:6, 1:7] = 2.0
    np.save(tmp_path / "l.npy", lab)
    report = mesh_blocks(tmp_path / "l.npy", tmp_path / "m.pvtu", workers=0, coarsen=1)
    assert report["n_elements"] == mesh_labels(lab, coarsen=1).n_cells
    lab[0, 0, 0] = 0.5
    np.save(tmp_path / "k.npy", lab)
    with pytest.raises(ValueError, match="non-integer labels"):
        mesh_blocks(tmp_path / "k.npy", tmp_path / "n.pvtu", workers=0, coarsen=1)
    assert not (tmp_path / "n.pvtu").exists() and not (tmp_path / "n").exists()
