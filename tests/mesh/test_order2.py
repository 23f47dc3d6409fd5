"""Second-order files: one node per edge midpoint, shared, in each format's node order.

meshio turns every format's order into VTK's, so one check (node d+1+k at the midpoint of
VTK's edge k) covers the formats it reads; Gmsh, Triangle and TetGen orders are checked
against the programs (gmsh's API, Triangle's own ``-o2`` output) and their documented
tables.
"""

from __future__ import annotations

import re

import meshio
import numpy as np
import pytest
from test_export import NEEDS_H5PY, canonical, sample_mesh

from napari_swa_imesh.mesh import read_mesh, write_mesh

VTK_EDGES = {2: [(0, 1), (1, 2), (2, 0)], 3: [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]}


def n_edges(cells) -> int:
    """Unique edges, counted independently of the writer (a set of sorted pairs)."""
    k = cells.shape[1]
    return len({tuple(sorted((c[i], c[j]))) for c in cells.tolist()
                for i in range(k) for j in range(i + 1, k)})


def assert_midpoints(points, cells, edges, ndim):
    corners = points[cells[:, :ndim + 1]]
    for k, (i, j) in enumerate(edges):
        np.testing.assert_array_equal(points[cells[:, ndim + 1 + k]],
                                      (corners[:, i] + corners[:, j]) / 2, err_msg=str((i, j)))


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("suffix", [".vtu", ".vtk", ".msh", ".inp",
                                    pytest.param(".xdmf", marks=NEEDS_H5PY)])
def test_meshio_reads_second_order_cells_with_nodes_at_edge_midpoints(tmp_path, ndim, suffix):
    mesh = sample_mesh(ndim)
    path = write_mesh(mesh, tmp_path / f"m{suffix}", order=2)[0]
    if suffix == ".inp" and ndim == 2:
        # meshio knows the plane-strain CPE6 but not CPS6: same nodes, so read it as that
        path.write_text(path.read_text().replace("TYPE=CPS6", "TYPE=CPE6"))
    m = meshio.read(path)
    kind = "triangle6" if ndim == 2 else "tetra10"
    blocks = [b.data for b in m.cells if b.type == kind]
    cells = np.concatenate(blocks)
    assert len(cells) == mesh.n_cells
    points = m.points[:, :ndim]
    assert_midpoints(points, cells, VTK_EDGES[ndim], ndim)
    # one node per corner and per unique edge, shared by the elements around it
    assert len(np.unique(cells)) == len(mesh.points) + n_edges(mesh.cells)
    assert len(np.unique(points, axis=0)) == len(points)
    # positive in the file's frame
    c = points[cells[:, :ndim + 1]]
    assert (np.linalg.det(c[:, 1:] - c[:, :1]) > 0).all()
    # and reading it gives the linear mesh back
    back = read_mesh(path)
    np.testing.assert_array_equal(canonical(back.points, back.cells, back.material),
                                  canonical(mesh.points, mesh.cells, mesh.material))


@pytest.mark.parametrize("ndim", [2, 3])
def test_gmsh_reads_second_order_elements_and_facets(tmp_path, ndim):
    gmsh = pytest.importorskip("gmsh")
    mesh = sample_mesh(ndim)
    path = write_mesh(mesh, tmp_path / "m.msh", order=2)[0]
    gmsh.initialize(["", "-v", "0"])
    try:
        gmsh.open(str(path))
        types, tags, nodes = gmsh.model.mesh.getElements(ndim)
        facet_types, _, _ = gmsh.model.mesh.getElements(ndim - 1)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        quality = gmsh.model.mesh.getElementQualities(tags[0], "minSICN")
        names = [gmsh.model.getPhysicalName(ndim - 1, t)
                 for _, t in gmsh.model.getPhysicalGroups(ndim - 1)]
    finally:
        gmsh.finalize()
    assert list(types) == [9 if ndim == 2 else 11] and len(tags[0]) == mesh.n_cells
    assert set(facet_types) == {8 if ndim == 2 else 9}
    assert "xmin" in names and quality.min() > 0
    # Gmsh's own tet10 order: nodes 8 and 9 on edges 2-3 and 1-3 (VTK has them swapped)
    xyz = np.empty((int(node_tags.max()) + 1, 3))
    xyz[node_tags.astype(int)] = coords.reshape(-1, 3)
    cells = nodes[0].reshape(mesh.n_cells, -1).astype(int)
    edges = VTK_EDGES[ndim] if ndim == 2 else [(0, 1), (1, 2), (2, 0), (0, 3), (2, 3), (1, 3)]
    assert_midpoints(xyz[:, :ndim], cells, edges, ndim)


def _table(path, skip_header=True):
    rows = [ln.split() for ln in path.read_text().splitlines()
            if ln.strip() and not ln.startswith("#")]
    return np.array(rows[1:] if skip_header else rows, dtype=float)


def test_triangle_o2_order_is_triangle_own(tmp_path):
    """Triangle rebuilds our mesh with -o2; its extra nodes and ours sit on the same edges."""
    triangle = pytest.importorskip("triangle")
    mesh = sample_mesh(2)
    write_mesh(mesh, tmp_path / "m.node", order=2)
    ours = triangle.load(str(tmp_path), "m")
    assert ours["triangles"].shape == (mesh.n_cells, 6)
    theirs = triangle.triangulate({"vertices": ours["vertices"][:len(mesh.points)],
                                   "triangles": ours["triangles"][:, :3]}, "ro2")
    opposite = [(1, 2), (2, 0), (0, 1)]               # the k-th extra node faces corner k
    assert_midpoints(theirs["vertices"], theirs["triangles"], opposite, 2)
    assert_midpoints(ours["vertices"], ours["triangles"], opposite, 2)


def test_tetgen_o2_order_and_face_file(tmp_path):
    mesh = sample_mesh(3)
    node, ele, face = write_mesh(mesh, tmp_path / "m.node", order=2)
    points = _table(node)[:, 1:]
    elements = _table(ele)
    assert elements.shape[1] == 1 + 10 + 1                   # index, 10 nodes, region
    cells = elements[:, 1:11].astype(int) - 1
    # TetGen 1.6 (highorder(), edge2ver): edges 23 03 01 12 13 02 after the corners
    assert_midpoints(points, cells, [(2, 3), (0, 3), (0, 1), (1, 2), (1, 3), (0, 2)], 3)
    faces = _table(face)[:, 1:7].astype(int)
    faces[:, :6] -= 1
    # boundary faces as TetGen -o2 writes them: corners a b c, then ab bc ca
    assert_midpoints(points, faces, [(0, 1), (1, 2), (2, 0)], 2)
    assert re.search(r"^# marker 1 xmin$", face.read_text(), re.M)
    np.testing.assert_array_equal(read_mesh(node).n_cells, mesh.n_cells)


@pytest.mark.parametrize("ndim", [2, 3])
def test_second_order_facets_in_the_companion_file(tmp_path, ndim):
    pv = pytest.importorskip("pyvista")
    mesh = sample_mesh(ndim)
    write_mesh(mesh, tmp_path / "m.vtu", order=2)
    grid = pv.read(tmp_path / "m_facets.vtu")
    kind = 21 if ndim == 2 else 22                           # quadratic edge / triangle
    facets = grid.cells_dict[kind]
    edges = [(0, 1)] if ndim == 2 else VTK_EDGES[2]
    assert_midpoints(np.asarray(grid.points)[:, :ndim], facets, edges, ndim - 1)
    main = pv.read(tmp_path / "m.vtu")
    assert main.n_points == grid.n_points and set(main.celltypes) == {22 if ndim == 2 else 24}


@pytest.mark.parametrize("order", [3, 0, 1.5, True, "2"])
def test_other_orders_are_refused_before_writing(tmp_path, order):
    with pytest.raises(ValueError, match="order must be 1 \\(linear\\) or 2"):
        write_mesh(sample_mesh(2), tmp_path / "m.vtu", order=order)
    assert list(tmp_path.iterdir()) == []
