"""Facet groups in every format that holds them, read back by the programs that use them.

Each file is checked against :func:`facet_groups` (the API): the same facets per group,
every boundary facet and every interface facet exactly once, facets oriented out of their
owner in the file's own coordinates, names and ids as documented.
"""

from __future__ import annotations

import re

import meshio
import numpy as np
import pytest
from test_export import NEEDS_H5PY, grid_mesh, sample_mesh

from napari_swa_imesh.mesh import facet_groups, mesh_labels, write_mesh
from napari_swa_imesh.mesh.checks._facets import paired_facets


def _rows(a) -> np.ndarray:
    """Rows sorted within and then among themselves (orientation- and order-free)."""
    a = np.sort(np.asarray(a, dtype=np.int64), axis=1)
    return a[np.lexsort(a.T[::-1])]


def _expected(mesh) -> dict[str, np.ndarray]:
    return {name: _rows(g.facets) for name, g in facet_groups(mesh).items()}


def _every_boundary_and_interface_facet(mesh) -> np.ndarray:
    """From the pairing alone: facets with one owner, or two of different materials."""
    facets, owners, _ = paired_facets(mesh.cells)
    mat = mesh.material
    other = np.where(owners[:, 1] >= 0, mat[owners[:, 1]], -1)
    keep = (owners[:, 1] < 0) | (mat[owners[:, 0]] != other)
    return _rows(facets[keep])


def _outward(points, cells, facets, owner) -> np.ndarray:
    """Signed volume of (owner's corner off the facet, facet...) in the file's frame."""
    opposite = np.array([np.setdiff1d(cells[o], f)[0] for o, f in zip(owner, facets)])
    simplex = points[np.column_stack([opposite, facets])]
    return np.linalg.det(simplex[:, 1:] - simplex[:, :1])


def labelled_mesh(ndim):
    """Three materials, one excluded so that exterior groups exist too."""
    rng = np.random.default_rng(3)
    shape = (9, 11) if ndim == 2 else (5, 6, 7)
    labels = rng.integers(1, 4, shape)
    labels[(slice(2, 5),) * ndim] = 0                      # an inner hole: exterior faces
    return mesh_labels(labels, spacing=(0.5,) * ndim, exclude=(0,),
                       material_names={1: "bone", 2: "soft tissue"})


# ----------------------------------------------------------------------------- .msh


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("ndim", [2, 3])
def test_gmsh_reads_facet_groups_as_physical_groups_of_one_dimension_less(tmp_path, ndim,
                                                                          binary):
    gmsh = pytest.importorskip("gmsh")
    mesh = labelled_mesh(ndim)
    expected = facet_groups(mesh)
    assert any(n.startswith("exterior_") for n in expected)
    path = write_mesh(mesh, tmp_path / "m.msh", binary=binary)[0]
    gmsh.initialize(["", "-v", "0"])
    try:
        gmsh.open(str(path))
        counts, tags = {}, {}
        for dim in (ndim, ndim - 1):
            for _, tag in gmsh.model.getPhysicalGroups(dim):
                name = gmsh.model.getPhysicalName(dim, tag)
                tags[name] = (dim, tag)
                counts[name] = sum(len(gmsh.model.mesh.getElements(dim, e)[1][0])
                                   for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag))
        _, volume_tags, _ = gmsh.model.mesh.getElements(ndim)
        quality = gmsh.model.mesh.getElementQualities(np.concatenate(volume_tags), "minSICN")
    finally:
        gmsh.finalize()
    assert {n: c for n, c in counts.items() if tags[n][0] == ndim - 1} == {
        n: len(g) for n, g in expected.items()}
    assert [tags[n] for n in expected] == [(ndim - 1, k + 1) for k in range(len(expected))]
    assert counts["bone"] == np.count_nonzero(mesh.material == 1)
    assert counts["soft tissue"] == np.count_nonzero(mesh.material == 2)
    assert len(quality) == mesh.n_cells and quality.min() > 0


@pytest.mark.parametrize("ndim", [2, 3])
def test_meshio_reads_the_gmsh_facet_elements(tmp_path, ndim):
    mesh = labelled_mesh(ndim)
    path = write_mesh(mesh, tmp_path / "m.msh")[0]
    m = meshio.read(path)
    facet_type = "line" if ndim == 2 else "triangle"
    tag_to_name = {int(t): n for n, (t, d) in m.field_data.items() if d == ndim - 1}
    got: dict[str, list] = {}
    for block, physical in zip(m.cells, m.cell_data["gmsh:physical"]):
        if block.type == facet_type:
            got.setdefault(tag_to_name[int(physical[0])], []).append(block.data)
    expected = _expected(mesh)
    assert list(got) == list(expected)
    for name, blocks in got.items():
        np.testing.assert_array_equal(_rows(np.concatenate(blocks)), expected[name], name)
    every = _rows(np.concatenate([np.concatenate(b) for b in got.values()]))
    np.testing.assert_array_equal(every, _every_boundary_and_interface_facet(mesh))
    # oriented out of the element they bound, in the file's own coordinates
    volume = np.concatenate([b.data for b in m.cells if b.type != facet_type])
    owners = np.concatenate([g.owner for g in facet_groups(mesh).values()])
    facets = np.concatenate([np.concatenate(b) for b in got.values()])
    # the file groups elements by material: find each owner's row there by its corners
    key = {tuple(sorted(c)): c for c in volume.tolist()}
    owner_cells = np.array([key[tuple(sorted(c))] for c in mesh.cells[owners].tolist()])
    assert (_outward(m.points[:, :ndim], owner_cells, facets,
                     np.arange(len(facets))) > 0).all()


# ----------------------------------------------------------------------------- .vtu


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("suffix", [".vtu", pytest.param(".xdmf", marks=NEEDS_H5PY)])
def test_companion_file_read_by_pyvista_and_meshio(tmp_path, ndim, suffix):
    pv = pytest.importorskip("pyvista")
    mesh = labelled_mesh(ndim)
    written = write_mesh(mesh, tmp_path / f"m{suffix}")
    companion = tmp_path / {".vtu": "m_facets.vtu", ".xdmf": "m_xdmf_facets.vtu"}[suffix]
    assert written[-1] == companion
    expected = facet_groups(mesh)
    ids = {name: k + 1 for k, name in enumerate(expected)}

    grid = pv.read(companion)
    assert {name: int(grid.field_data[name][0]) for name in expected} == ids
    group, owner = grid.cell_data["group"], grid.cell_data["owner"]
    cells = grid.cells_dict[3 if ndim == 2 else 5]        # VTK_LINE, VTK_TRIANGLE
    assert len(cells) == grid.n_cells == sum(len(g) for g in expected.values())
    for name, g in expected.items():
        mine = group == ids[name]
        np.testing.assert_array_equal(_rows(cells[mine]), _rows(g.facets), name)
        np.testing.assert_array_equal(np.sort(owner[mine]), np.sort(g.owner))
    np.testing.assert_array_equal(_rows(cells), _every_boundary_and_interface_facet(mesh))

    m = meshio.read(companion)
    assert m.cells[0].type == ("line" if ndim == 2 else "triangle")
    assert {n: v.tolist() for n, v in m.field_data.items()} == {n: [i] for n, i in ids.items()}
    np.testing.assert_array_equal(m.cell_data["group"][0], group)
    # same points as the mesh file, so facet corners are its node ids; outward facets
    main = meshio.read(written[0])
    np.testing.assert_array_equal(m.points[:, :ndim], main.points[:, :ndim])
    assert (_outward(main.points[:, :ndim], main.cells[0].data, m.cells[0].data,
                     m.cell_data["owner"][0]) > 0).all()


# ----------------------------------------------------------------------------- .node/.ele


def _marker_file(path):
    text = path.read_text()
    names = {int(i): n for i, n in re.findall(r"^# marker (\d+) (.+)$", text, re.M)}
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    return names, rows


def test_tetgen_face_file_holds_every_group_as_a_marker(tmp_path):
    mesh = labelled_mesh(3)
    node, ele, face = write_mesh(mesh, tmp_path / "m.node")
    assert face.name == "m.face"
    names, rows = _marker_file(face)
    expected = facet_groups(mesh)
    assert names == {k + 1: n for k, n in enumerate(expected)}
    header, body = rows[0], np.array(rows[1:], dtype=np.int64)
    assert header == [str(len(body)), "1"]
    np.testing.assert_array_equal(body[:, 0], np.arange(1, len(body) + 1))
    for marker, name in names.items():
        facets = body[body[:, -1] == marker, 1:4] - 1
        np.testing.assert_array_equal(_rows(facets), _rows(expected[name].facets), name)
    np.testing.assert_array_equal(_rows(body[:, 1:4] - 1),
                                  _every_boundary_and_interface_facet(mesh))


def test_triangle_reads_the_poly_segments_and_markers(tmp_path):
    triangle = pytest.importorskip("triangle")
    mesh = labelled_mesh(2)
    *_, poly = write_mesh(mesh, tmp_path / "m.ele")
    assert poly.name == "m.poly"
    names, _ = _marker_file(poly)
    data = triangle.load(str(tmp_path), "m")              # .node, .ele and .poly
    expected = facet_groups(mesh)
    assert names == {k + 1: n for k, n in enumerate(expected)}
    for marker, name in names.items():
        segments = data["segments"][data["segment_markers"][:, 0] == marker]
        np.testing.assert_array_equal(_rows(segments), _rows(expected[name].facets), name)
    np.testing.assert_array_equal(_rows(data["segments"]),
                                  _every_boundary_and_interface_facet(mesh))


# ----------------------------------------------------------------------------- choosing


@pytest.mark.parametrize("suffix", [".msh", ".inp", ".vtu", ".node"])
def test_chosen_groups_only_with_ids_in_facet_groups_order(tmp_path, suffix):
    mesh = labelled_mesh(3)
    written = write_mesh(mesh, tmp_path / f"m{suffix}",
                         facet_groups=["interface_*", "xmax", "xmin"])
    names = ["xmin", "xmax"] + [n for n in facet_groups(mesh) if n.startswith("interface_")]
    if suffix == ".msh":
        m = meshio.read(written[0])
        assert {n: v.tolist() for n, v in m.field_data.items() if v[1] == 2} == {
            n: [k + 1, 2] for k, n in enumerate(names)}
    elif suffix == ".inp":
        text = written[0].read_text()
        assert re.findall(r"^\*SURFACE, NAME=(\w+)", text, re.M) == [
            re.sub(r"\W", "_", n) for n in names]
    elif suffix == ".vtu":
        assert list(meshio.read(written[1]).field_data) == names
    else:
        assert list(_marker_file(written[2])[0].values()) == names


@NEEDS_H5PY
def test_vtu_and_xdmf_of_one_mesh_share_a_folder(tmp_path):
    mesh = labelled_mesh(3)
    vtu = write_mesh(mesh, tmp_path / "mesh.vtu")
    xdmf = write_mesh(mesh, tmp_path / "mesh.xdmf")
    assert [p.name for p in vtu + xdmf] == ["mesh.vtu", "mesh_facets.vtu", "mesh.xdmf",
                                            "mesh.h5", "mesh_xdmf_facets.vtu"]
    a, b = meshio.read(vtu[1]), meshio.read(xdmf[2])
    np.testing.assert_array_equal(a.cells[0].data, b.cells[0].data)
    np.testing.assert_array_equal(a.cell_data["group"][0], b.cell_data["group"][0])


@pytest.mark.parametrize("suffix", [".msh", ".inp", ".vtu", ".xdmf", ".node"])
def test_no_groups_writes_no_group_file_and_no_group(tmp_path, suffix):
    if suffix == ".xdmf":
        pytest.importorskip("h5py")
    mesh = sample_mesh(3)
    written = write_mesh(mesh, tmp_path / f"m{suffix}", facet_groups="none")
    assert [p.name for p in written] == {".node": ["m.node", "m.ele"],
                                         ".xdmf": ["m.xdmf", "m.h5"]}.get(suffix, [f"m{suffix}"])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in written)
    if suffix == ".msh":
        assert all(d == 3 for _, d in meshio.read(written[0]).field_data.values())
    if suffix == ".inp":
        assert "*NSET" not in written[0].read_text()


def test_unknown_groups_fail_before_anything_is_written(tmp_path):
    mesh = grid_mesh(np.array([[[1, 2]]]), names={1: "bone", 2: "soft"})
    (tmp_path / "keep.txt").write_text("user")
    with pytest.raises(ValueError, match=r"facet group 'interface_bone_skin' is not in this "
                                         r"mesh; its groups are xmin, xmax.*interface_bone_soft"):
        write_mesh(mesh, tmp_path / "m.vtu", facet_groups=["xmin", "interface_bone_skin"])
    with pytest.raises(ValueError, match="facet group 'exterior_\\*' is not in this mesh"):
        write_mesh(mesh, tmp_path / "m.msh", facet_groups=["exterior_*"])
    with pytest.raises(ValueError, match=r"unknown facet group 'zmin'; the groups are xmin, "
                                         r"xmax, ymin, ymax, interface_<A>_<B>"):
        write_mesh(sample_mesh(2), tmp_path / "m.inp", facet_groups=["zmin"])
    with pytest.raises(ValueError, match="must be 'all', 'none' or a list of group names"):
        write_mesh(mesh, tmp_path / "m.inp", facet_groups="xmin")
    with pytest.raises(ValueError, match="legacy .vtk holds no facet groups"):
        write_mesh(mesh, tmp_path / "m.vtk", facet_groups=["xmin"])
    with pytest.raises(ValueError, match="binary=False \\(ASCII\\) applies to .msh only"):
        write_mesh(mesh, tmp_path / "m.vtu", binary=False)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]
