"""Round trips of every export format, orientation, names and refusals to overwrite."""

from __future__ import annotations

import importlib.util
import itertools
import re
import shutil
import sys

import meshio
import numpy as np
import pytest
from gmsh_helpers import gmsh_reads

from napari_swa_imesh.mesh.formats._export import MESH_SUFFIXES, read_mesh, to_meshio, write_mesh
from napari_swa_imesh.mesh.formats._triangle_tetgen import read_node_ele
from napari_swa_imesh.mesh.model._types import Mesh

ALL_FORMATS = [".vtu", ".vtk", ".msh", ".xdmf", ".inp", ".node"]
HAVE_H5PY = importlib.util.find_spec("h5py") is not None
NEEDS_H5PY = pytest.mark.skipif(not HAVE_H5PY, reason="meshio's XDMF needs h5py, not installed")
# formats this machine can write (loops), and the same as parameters (XDMF shown as skipped)
FORMATS = [s for s in ALL_FORMATS if s != ".xdmf" or HAVE_H5PY]
FORMAT_PARAMS = [pytest.param(s, marks=NEEDS_H5PY) if s == ".xdmf" else s for s in ALL_FORMATS]
NAMES = {1: "bone", 2: "soft tissue"}


def grid_mesh(labels, spacing=None, names=None) -> Mesh:
    """Kuhn simplices of every pixel/voxel (2 triangles, 6 tetrahedra), one material each.

    Built independently of the mesher: cube corner + unit steps along each permutation
    of the axes, oriented positive by the sign of the edge determinant.
    """
    labels = np.asarray(labels)
    d = labels.ndim
    spacing = np.ones(d) if spacing is None else np.asarray(spacing, dtype=float)
    vertex_shape = tuple(s + 1 for s in labels.shape)
    points = np.indices(vertex_shape).reshape(d, -1).T * spacing  # (N, d)
    origin = np.indices(labels.shape).reshape(d, -1).T  # (V, d) lowest corner per voxel
    cells = []
    for perm in itertools.permutations(range(d)):
        steps = np.zeros((d + 1, d), dtype=int)
        for k, axis in enumerate(perm):
            steps[k + 1 :, axis] = 1
        corners = [np.ravel_multi_index((origin + s).T, vertex_shape) for s in steps]
        cells.append(np.stack(corners, axis=1))
    cells = np.concatenate(cells)  # (V * d!, d+1)
    material = np.tile(labels.reshape(-1), len(cells) // labels.size).astype(np.int64)
    edges = points[cells[:, 1:]] - points[cells[:, :1]]
    flip = np.linalg.det(edges) < 0
    cells[flip, 0], cells[flip, 1] = cells[flip, 1], cells[flip, 0].copy()
    rng = np.random.default_rng(7)
    cell_data = {
        "quality": rng.uniform(0.7, 1.2, len(cells)),
        "level": rng.integers(0, 4, len(cells)).astype(np.int8),  # as the mesher stores it
    }
    return Mesh(points, cells, material, cell_data, spacing=tuple(spacing),
                shape=labels.shape, material_names=dict(names or {}))


def sample_mesh(ndim: int) -> Mesh:
    rng = np.random.default_rng(ndim)
    shape = (4, 5) if ndim == 2 else (2, 3, 4)
    labels = rng.integers(0, 4, size=shape)
    spacing = (0.5, 0.25) if ndim == 2 else (2.0, 0.5, 0.25)
    return grid_mesh(labels, spacing, NAMES)


def canonical(points: np.ndarray, cells: np.ndarray, *others: np.ndarray) -> np.ndarray:
    """Cells as sorted rows of sorted corner coordinates (+ per-cell values), order-free."""
    corners = np.round(points[cells], 9)  # (M, d+1, d)
    keys = np.array([sorted(map(tuple, c)) for c in corners]).reshape(len(cells), -1)
    rows = np.column_stack([keys, *others]) if others else keys
    return rows[np.lexsort(rows.T[::-1])]


def signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    return np.linalg.det(points[cells[:, 1:]] - points[cells[:, :1]])


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("suffix", FORMAT_PARAMS)
def test_round_trip_keeps_points_cells_and_materials(tmp_path, ndim, suffix):
    mesh = sample_mesh(ndim)
    written = write_mesh(mesh, tmp_path / f"mesh{suffix}")
    assert all(p.is_file() for p in written)
    back = read_mesh(written[0])
    assert back.points.shape[1] == ndim
    assert back.n_cells == mesh.n_cells
    np.testing.assert_array_equal(
        canonical(back.points, back.cells, back.material),
        canonical(mesh.points, mesh.cells, mesh.material),
    )
    assert (signed_volumes(back.points, back.cells) > 0).all()
    holds_quality = suffix not in (".inp",) and not (suffix == ".node" and ndim == 3)
    if holds_quality:
        np.testing.assert_allclose(
            canonical(back.points, back.cells, back.quality),
            canonical(mesh.points, mesh.cells, mesh.quality),
            rtol=1e-12,
        )


@pytest.mark.parametrize("ndim", [2, 3])
def test_unique_points_survive_exactly(tmp_path, ndim):
    mesh = sample_mesh(ndim)
    for suffix in FORMATS:
        back = read_mesh(write_mesh(mesh, tmp_path / f"m_{suffix[1:]}{suffix}")[0])
        np.testing.assert_array_equal(
            np.unique(back.points, axis=0), np.unique(mesh.points, axis=0), err_msg=suffix
        )


@pytest.mark.parametrize("ndim", [2, 3])
def test_to_meshio_reverses_axes_and_keeps_volumes_positive(ndim):
    mesh = sample_mesh(ndim)
    m = to_meshio(mesh)
    np.testing.assert_array_equal(m.points, mesh.points[:, ::-1])
    assert m.cells[0].type == ("triangle" if ndim == 2 else "tetra")
    assert (signed_volumes(m.points, m.cells[0].data) > 0).all()
    np.testing.assert_array_equal(m.cell_data["material"][0], mesh.material)
    assert set(m.cell_data) == {"material", "quality", "level"}
    # same cells, only reordered within each cell
    np.testing.assert_array_equal(np.sort(m.cells[0].data, axis=1), np.sort(mesh.cells, axis=1))


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("suffix", [s for s in FORMAT_PARAMS if s != ".node"])
def test_files_read_by_meshio_are_positively_oriented(tmp_path, ndim, suffix):
    mesh = sample_mesh(ndim)
    path = write_mesh(mesh, tmp_path / f"mesh{suffix}")[0]
    m = meshio.read(path)
    points = m.points[:, :ndim]
    for block in m.cells:
        if block.type == ("triangle" if ndim == 2 else "tetra"):  # not the facet blocks
            assert (signed_volumes(points, block.data) > 0).all()
    # Gmsh files come back with nodes grouped by entity, so compare point sets
    np.testing.assert_array_equal(np.unique(points, axis=0),
                                  np.unique(mesh.points[:, ::-1], axis=0))


@pytest.mark.parametrize("ndim", [2, 3])
def test_node_ele_follows_the_documented_layout(tmp_path, ndim):
    mesh = sample_mesh(ndim)
    node, ele, facets = write_mesh(mesh, tmp_path / "mesh.ele")
    assert (node.name, ele.name) == ("mesh.node", "mesh.ele")
    assert facets.name == ("mesh.poly" if ndim == 2 else "mesh.face")
    header = [ln for ln in ele.read_text().splitlines() if not ln.startswith("#")][0]
    n_attr = 2 if ndim == 2 else 1  # Triangle: material, quality; TetGen: region attribute
    assert header.split() == [str(mesh.n_cells), str(ndim + 1), str(n_attr)]
    node_header = [ln for ln in node.read_text().splitlines() if not ln.startswith("#")][0]
    assert node_header.split() == [str(len(mesh.points)), str(ndim), "0", "0"]
    points, cells, attributes = read_node_ele((node, ele))
    assert cells.min() == 0  # 1-based in the file, 0-based back
    # Triangle wants counterclockwise corners in (x, y), TetGen positive volume
    assert (signed_volumes(points, cells) > 0).all()
    np.testing.assert_array_equal(np.sort(attributes["material"]), np.sort(mesh.material))


def test_tetgen_files_read_by_meshio(tmp_path):
    mesh = sample_mesh(3)
    node, *_ = write_mesh(mesh, tmp_path / "mesh.node")
    m = meshio.read(node)
    np.testing.assert_array_equal(m.points, mesh.points[:, ::-1])
    np.testing.assert_array_equal(m.cell_data["tetgen:ref"][0], mesh.material)


def test_node_ele_reader_accepts_zero_based_files(tmp_path):
    (tmp_path / "a.node").write_text("3 2 0 0\n0 0 0\n1 1 0\n2 0 1\n")
    (tmp_path / "a.ele").write_text("# one triangle\n1 3 1\n0 0 1 2 5\n")
    mesh = read_mesh(tmp_path / "a.ele")
    np.testing.assert_array_equal(np.sort(mesh.cells[0]), [0, 1, 2])
    assert mesh.material.tolist() == [5]


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("ndim", [2, 3])
def test_gmsh_physical_groups_are_named_after_materials(tmp_path, ndim, binary):
    mesh = sample_mesh(ndim)
    path = write_mesh(mesh, tmp_path / "mesh.msh", binary=binary)[0]
    text = path.read_bytes()
    assert text.startswith(f"$MeshFormat\n4.1 {int(binary)} 8\n".encode())
    assert f'{ndim} 1 "bone"'.encode() in text and f'{ndim} 2 "soft tissue"'.encode() in text
    assert f'{ndim} 3 "material_3"'.encode() in text
    m = meshio.read(path)
    assert m.field_data["bone"].tolist() == [1, ndim]
    assert m.field_data["soft tissue"].tolist() == [2, ndim]
    # every element's physical group is its material (material 0 gets tag max+1 = 4);
    # the facet blocks (one dimension less) follow
    blocks = [i for i, b in enumerate(m.cells) if b.type == ("triangle", "tetra")[ndim - 2]]
    assert blocks == list(range(len(blocks)))
    physical = np.concatenate([m.cell_data["gmsh:physical"][i] for i in blocks])
    material = np.concatenate([m.cell_data["material"][i] for i in blocks]).astype(int)
    np.testing.assert_array_equal(np.where(material == 0, 4, material), physical)
    assert read_mesh(path).material_names[2] == "soft tissue"


@pytest.mark.parametrize("ndim", [2, 3])
def test_abaqus_has_one_element_set_per_material(tmp_path, ndim):
    mesh = sample_mesh(ndim)
    path = write_mesh(mesh, tmp_path / "mesh.inp")[0]
    text = path.read_text()
    for name in ("bone", "soft_tissue", "material_3", "material_0"):
        assert f"*ELSET, ELSET={name}\n" in text
    assert ("*ELEMENT, TYPE=CPS3" if ndim == 2 else "*ELEMENT, TYPE=C3D4") in text
    m = meshio.read(path)
    sets = {name: np.concatenate(v) for name, v in m.cell_sets.items()}
    np.testing.assert_array_equal(np.sort(sets["bone"]), np.flatnonzero(mesh.material == 1))
    materials = ("bone", "soft_tissue", "material_3", "material_0")
    assert sum(len(v) for k, v in sets.items() if k in materials) == mesh.n_cells
    # the other element sets hold the faces of the facet groups (<group>_S<k>)
    assert all(re.fullmatch(r"\w+_S[1-4]", k) for k in sets if k not in materials)
    assert "*SURFACE, NAME=xmin, TYPE=ELEMENT" in text and "*NSET, NSET=ymax" in text


def test_abaqus_heat_elements_on_request(tmp_path):
    path = write_mesh(sample_mesh(3), tmp_path / "mesh.inp", abaqus_elements="heat")[0]
    assert "*ELEMENT, TYPE=DC3D4" in path.read_text()
    with pytest.raises(ValueError, match="abaqus_elements must be one of mechanical, heat"):
        write_mesh(sample_mesh(3), tmp_path / "other.inp", abaqus_elements="thermal")
    assert not (tmp_path / "other.inp").exists()


def test_material_zero_and_unnamed_materials(tmp_path):
    mesh = grid_mesh(np.array([[0, 5], [5, 0]]))
    back = read_mesh(write_mesh(mesh, tmp_path / "m.msh")[0])
    assert back.material_names == {0: "material_0", 5: "material_5"}
    np.testing.assert_array_equal(np.sort(back.material), np.sort(mesh.material))


def test_refuses_to_overwrite_without_force(tmp_path):
    mesh = sample_mesh(2)
    target = tmp_path / "mesh.vtu"
    target.write_text("user data")
    with pytest.raises(FileExistsError, match="already exists.*force"):
        write_mesh(mesh, target)
    assert target.read_text() == "user data"
    write_mesh(mesh, target, force=True)
    assert read_mesh(target).n_cells == mesh.n_cells
    # no temporary left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.vtu", "mesh_facets.vtu"]


def test_node_ele_checks_both_files_before_writing_either(tmp_path):
    mesh = sample_mesh(3)
    (tmp_path / "mesh.ele").write_text("user elements")
    with pytest.raises(FileExistsError, match="mesh.ele"):
        write_mesh(mesh, tmp_path / "mesh.node")
    assert not (tmp_path / "mesh.node").exists()
    assert (tmp_path / "mesh.ele").read_text() == "user elements"


def test_unknown_suffix_lists_the_supported_ones(tmp_path):
    with pytest.raises(ValueError, match=r"unknown suffix '\.stl'.*\.vtu.*\.msh.*\.inp"):
        write_mesh(sample_mesh(2), tmp_path / "mesh.stl")
    with pytest.raises(ValueError, match="unknown suffix '\\(none\\)'"):
        write_mesh(sample_mesh(2), tmp_path / "mesh")
    assert list(tmp_path.iterdir()) == []


def test_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        write_mesh(sample_mesh(2), tmp_path / "nowhere" / "mesh.vtu")


def test_bad_mesh_arguments(tmp_path):
    with pytest.raises(TypeError, match="expected a napari_swa_imesh Mesh"):
        write_mesh(meshio.Mesh(np.zeros((3, 2)), [("triangle", [[0, 1, 2]])]), tmp_path / "x.vtu")
    mesh = sample_mesh(2)
    with pytest.raises(ValueError, match="one id per element"):
        Mesh(mesh.points, mesh.cells, mesh.material[:-1], mesh.cell_data)
    twins = Mesh(mesh.points, mesh.cells, mesh.material, mesh.cell_data,
                 material_names={1: "bone", 2: "bone"})
    with pytest.raises(ValueError, match="share the name 'bone'"):
        write_mesh(twins, tmp_path / "x.msh")
    assert list(tmp_path.iterdir()) == []


def test_write_does_not_mutate_the_mesh(tmp_path):
    mesh = sample_mesh(3)
    before = (mesh.points.copy(), mesh.cells.copy(), mesh.material.copy(), mesh.quality.copy())
    for suffix in FORMATS:
        write_mesh(mesh, tmp_path / f"m_{suffix[1:]}{suffix}")
    for old, new in zip(before, (mesh.points, mesh.cells, mesh.material, mesh.quality)):
        np.testing.assert_array_equal(old, new)


def test_read_mesh_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no mesh file"):
        read_mesh(tmp_path / "missing.vtu")
    (tmp_path / "x.stl").write_text("solid")
    with pytest.raises(ValueError, match="unknown suffix"):
        read_mesh(tmp_path / "x.stl")
    (tmp_path / "lonely.node").write_text("0 2 0 0\n")
    with pytest.raises(FileNotFoundError, match="needs its .ele twin"):
        read_mesh(tmp_path / "lonely.node")


def test_suffix_table_matches_formats():
    assert set(ALL_FORMATS) | {".ele"} == set(MESH_SUFFIXES)


@NEEDS_H5PY
def test_xdmf_writes_its_h5_twin_and_checks_both(tmp_path):
    mesh = sample_mesh(3)
    written = write_mesh(mesh, tmp_path / "m.xdmf")
    assert [p.name for p in written] == ["m.xdmf", "m.h5", "m_xdmf_facets.vtu"]
    # no temporaries
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.h5", "m.xdmf", "m_xdmf_facets.vtu"]
    text = written[0].read_text()
    assert "m.h5:/" in text and ".swa-imesh-" not in text
    (tmp_path / "m.h5").write_bytes(b"user")
    (tmp_path / "m.xdmf").unlink()
    with pytest.raises(FileExistsError, match="m.h5"):
        write_mesh(mesh, tmp_path / "m.xdmf")
    assert not (tmp_path / "m.xdmf").exists()


def test_xdmf_without_h5py_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "h5py", None)  # makes `import h5py` fail
    with pytest.raises(ValueError, match=r'needs h5py.*pip install "napari-swa-imesh\[xdmf\]"'):
        write_mesh(sample_mesh(2), tmp_path / "m.xdmf")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("suffix", [".vtu", ".vtk"])
def test_vtk_itself_reads_the_files(tmp_path, ndim, suffix):
    pv = pytest.importorskip("pyvista")
    mesh = sample_mesh(ndim)
    grid = pv.read(write_mesh(mesh, tmp_path / f"m_{suffix[1:]}{suffix}")[0])
    assert grid.n_cells == mesh.n_cells
    np.testing.assert_array_equal(grid.cell_data["material"], mesh.material)
    sizes = grid.compute_cell_sizes(length=False, area=ndim == 2, volume=ndim == 3)
    size = sizes.cell_data["Area" if ndim == 2 else "Volume"]
    np.testing.assert_allclose(size.sum(), np.prod(np.array(mesh.shape) * mesh.spacing))


@pytest.mark.parametrize("ndim", [2, 3])
def test_gmsh_itself_reads_named_groups_and_positive_elements(tmp_path, ndim):
    mesh = sample_mesh(ndim)
    path = write_mesh(mesh, tmp_path / "m.msh")[0]
    tagged, quality = gmsh_reads(path, ndim)
    groups = {name: count for name, (_, count) in tagged.items()}
    assert groups["bone"] == np.count_nonzero(mesh.material == 1)
    assert groups["soft tissue"] == np.count_nonzero(mesh.material == 2)
    assert sum(groups.values()) == mesh.n_cells
    assert quality.min() > 0


@pytest.mark.parametrize(("shape", "spacing"),
                         [((9, 7), (0.5, 2.0)), ((5, 6, 7), (1.0, 0.5, 0.25))])
def test_mesher_output_passes_every_check_after_a_round_trip(tmp_path, shape, spacing):
    """Conforming, positive, volumes, labels recovered: from the file, not from memory."""
    import dataclasses

    from napari_swa_imesh.mesh.checks._checks import check_mesh
    from napari_swa_imesh.mesh.mesher._imesh import mesh_labels

    labels = np.random.default_rng(len(shape)).integers(0, 3, shape)
    mesh = mesh_labels(labels, spacing=spacing, exclude=(0,))
    for suffix in FORMATS:
        back = read_mesh(write_mesh(mesh, tmp_path / f"m_{suffix[1:]}{suffix}")[0])
        # the files hold no spacing or image shape: give back what the checks measure in
        back = dataclasses.replace(back, spacing=mesh.spacing, shape=mesh.shape)
        checks = check_mesh(back, labels, exclude=(0,))
        assert checks["all_passed"], (suffix, checks)


@pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX (ccx) is not installed")
def test_calculix_solves_on_the_abaqus_file(tmp_path):
    """A static gravity load on sections given by our element sets: runs, sags downward."""
    import subprocess

    mesh = grid_mesh(np.array([[[1, 2], [2, 1]], [[1, 1], [2, 2]]]), names=NAMES)
    write_mesh(mesh, tmp_path / "mesh.inp")
    bottom = np.flatnonzero(mesh.points[:, 0] == 0) + 1  # plane 0 = z 0, 1-based nodes
    sets = ",".join(map(str, bottom))
    deck = "\n".join([
        "*INCLUDE, INPUT=mesh.inp",
        "*MATERIAL, NAME=STIFF", "*ELASTIC", "1000., 0.3", "*DENSITY", "1e-3",
        "*SOLID SECTION, ELSET=bone, MATERIAL=STIFF",
        "*SOLID SECTION, ELSET=soft_tissue, MATERIAL=STIFF",
        f"*NSET, NSET=FIX\n{sets}", f"*NSET, NSET=ALL, GENERATE\n1, {len(mesh.points)}, 1",
        "*STEP", "*STATIC", "*BOUNDARY", "FIX, 1, 3, 0.",
        "*DLOAD", "bone, GRAV, 9.81, 0., 0., -1.", "soft_tissue, GRAV, 9.81, 0., 0., -1.",
        "*NODE PRINT, NSET=ALL", "U", "*END STEP", ""])
    (tmp_path / "run.inp").write_text(deck)
    result = subprocess.run(["ccx", "run"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=60)
    assert "ERROR" not in result.stdout and "Job finished" in result.stdout
    rows = [ln.split() for ln in (tmp_path / "run.dat").read_text().splitlines()
            if ln.split() and ln.split()[0].isdigit()]
    uz = np.array([float(r[3]) for r in rows])
    assert len(uz) == len(mesh.points) and uz.max() <= 0 and uz.min() < 0


def test_triangle_itself_rebuilds_the_mesh_from_our_files(tmp_path):
    triangle = pytest.importorskip("triangle", reason="the triangle package is optional")
    mesh = sample_mesh(2)
    write_mesh(mesh, tmp_path / "mesh.node")
    data = triangle.load(str(tmp_path), "mesh")
    rebuilt = triangle.triangulate(data, "r")  # -r: reconstruct the given mesh
    assert np.array_equal(np.unique(np.sort(rebuilt["triangles"], axis=1), axis=0),
                          np.unique(np.sort(data["triangles"], axis=1), axis=0))
    np.testing.assert_array_equal(rebuilt["triangle_attributes"][:, 0], mesh.material)


def test_reading_an_inp_of_element_types_meshio_lacks_says_what_to_do(tmp_path):
    from napari_swa_imesh.mesh import mesh_labels

    path = tmp_path / "m.inp"
    write_mesh(mesh_labels(np.array([[1, 2], [2, 1]])), path, order=2)   # CPS6
    with pytest.raises(ValueError, match="meshio does not know one of its element types"):
        read_mesh(path)
