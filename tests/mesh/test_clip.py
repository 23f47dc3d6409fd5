"""The "keep whole cells" clip against a brute-force reference and VTK's crinkle clip."""

from collections import Counter
from itertools import combinations

import numpy as np
import pytest
from imesh_cases import blobs, noise

from napari_swa_imesh.mesh import (
    Mesh,
    MeshClipper,
    clip_cells,
    mesh_labels,
    radius_edge_ratio,
    signed_volumes,
)


def _random_delaunay():
    """A mesh that is no octree's: tilted faces let two kept elements share a face
    with no vertex on the kept side (not met in the IMESH meshes above)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(7)
    points = rng.random((300, 3)) * 10
    cells = Delaunay(points).simplices
    flip = signed_volumes(points, cells) < 0
    cells[flip, :2] = cells[flip, 1::-1]
    return Mesh(points, cells, rng.integers(1, 3, len(cells)),
                {"quality": radius_edge_ratio(points, cells)})


MESHES = {
    "random-delaunay": _random_delaunay,
    "blobs": lambda: mesh_labels(blobs((9, 12, 10), 3, seed=4), spacing=(2.0, 1.0, 0.5)),
    "noise-excluded": lambda: mesh_labels(noise((8, 8, 8), 3, seed=5, p=0.1), exclude=[0]),
    "blobs-holes": lambda: mesh_labels(blobs((10, 9, 11), 3, seed=6), exclude=[1]),
}


def _reference(mesh, axis, position, keep):
    """Per element and per face, with Python loops: what the clip must give."""
    x = mesh.points[:, axis]
    kept = np.array([any((x[v] < position) if keep == "below" else (x[v] > position)
                         for v in cell) for cell in mesh.cells.tolist()])
    seen = Counter()
    for cell, k in zip(mesh.cells.tolist(), kept):
        if k:
            seen.update(combinations(sorted(cell), 3))   # its four faces
    return kept, {face for face, n in seen.items() if n == 1}


def _positions(mesh, axis):
    lo, hi = mesh.points[:, axis].min(), mesh.points[:, axis].max()
    on_vertices = np.unique(mesh.points[:, axis])          # ties: vertices on the plane
    rng = np.random.default_rng(axis)
    return [lo, hi, *on_vertices[len(on_vertices) // 3:: max(1, len(on_vertices) // 3)],
            *rng.uniform(lo, hi, 2)]


@pytest.mark.parametrize("name", sorted(MESHES))
@pytest.mark.parametrize("keep", ["below", "above"])
def test_the_clip_is_the_brute_force_one(name, keep):
    mesh = MESHES[name]()
    clipper = MeshClipper(mesh)
    volumes = signed_volumes(mesh.points, mesh.cells)
    for axis in range(3):
        x = mesh.points[:, axis]
        for position in _positions(mesh, axis):
            kept, faces, owner = clipper.faces(axis, position, keep=keep)
            ref_kept, ref_faces = _reference(mesh, axis, position, keep)
            np.testing.assert_array_equal(kept, ref_kept)
            np.testing.assert_array_equal(kept, clip_cells(mesh.points, mesh.cells, axis,
                                                           position, keep=keep))
            side = x[mesh.cells] < position if keep == "below" else x[mesh.cells] > position
            assert side[kept].any(axis=1).all()          # a vertex on the kept side each
            as_sets = [tuple(sorted(f)) for f in faces.tolist()]
            assert len(set(as_sets)) == len(as_sets)     # each face once
            assert set(as_sets) == ref_faces
            # each face is a face of its owner, which is kept
            assert kept[owner].all()
            assert all(set(f) <= set(c) for f, c in zip(faces.tolist(),
                                                        mesh.cells[owner].tolist()))
            # closed and oriented outward: every directed edge meets its reverse, and
            # the faces enclose the kept volume (divergence theorem)
            edges = Counter((a, b) for f in faces.tolist()
                            for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])))
            assert edges == Counter({(b, a): n for (a, b), n in edges.items()})
            p = mesh.points[faces]
            enclosed = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
            assert enclosed == pytest.approx(volumes[kept].sum(), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("keep", ["below", "above"])
def test_the_cut_exposes_the_elements_the_plane_cuts(keep):
    mesh = MESHES["blobs"]()
    axis, position = 1, 5.5                               # mid-volume, between vertices
    kept, faces, owner = MeshClipper(mesh).faces(axis, position, keep=keep)
    x = mesh.points[:, axis]
    on_side = (x < position) if keep == "below" else (x > position)
    # faces at the cut: none of their vertices on the kept side, owned by a cut element
    at_cut = ~on_side[faces].any(axis=1)
    assert at_cut.sum() > 100
    cut_owner = ~on_side[mesh.cells[owner[at_cut]]].all(axis=1)
    assert cut_owner.all()
    # and they lie across the whole cross-section: their area is at least the box's
    p = mesh.points[faces[at_cut]]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum() / 2
    lo, hi = mesh.image_box()
    assert area >= np.prod(np.delete(hi - lo, axis)) - 1e-9


def test_vtk_crinkle_clip_keeps_the_same_cells_and_surface():
    pytest.importorskip("pyvista")
    mesh = MESHES["noise-excluded"]()
    clipper = MeshClipper(mesh)
    grid = mesh.to_pyvista()
    grid.cell_data["element"] = np.arange(mesh.n_cells)
    normal = {0: "z", 1: "y", 2: "x"}           # exported x, y, z = column, row, plane
    for axis in range(3):
        for keep in ("below", "above"):
            position = 3.3
            origin = [0.0, 0.0, 0.0]
            origin[2 - axis] = position
            clipped = grid.clip(normal=normal[axis], origin=origin, invert=keep == "below",
                                crinkle=True)
            kept, faces, owner = clipper.faces(axis, position, keep=keep)
            np.testing.assert_array_equal(np.sort(clipped.cell_data["element"]),
                                          np.flatnonzero(kept))
            surface = clipped.extract_surface(algorithm=None).triangulate()
            theirs = {tuple(sorted(map(tuple, np.round(surface.points[f], 9).tolist())))
                      for f in surface.regular_faces}
            xyz = mesh.points[:, ::-1]
            ours = {tuple(sorted(map(tuple, np.round(xyz[f], 9).tolist())))
                    for f in faces}
            assert ours == theirs


def test_2d_keeps_the_triangles_themselves():
    mesh = mesh_labels(blobs((12, 10), 3, seed=2), spacing=(1.0, 2.0))
    clipper = MeshClipper(mesh)
    kept, faces, owner = clipper.faces(1, 9.0, keep="above")
    np.testing.assert_array_equal(owner, np.flatnonzero(kept))
    np.testing.assert_array_equal(faces, mesh.cells[kept])
    assert (mesh.points[faces, 1] > 9.0).any(axis=1).all()
    assert 0 < kept.sum() < mesh.n_cells


def test_the_surface_carries_the_kept_elements_values():
    mesh = MESHES["blobs"]()
    surface = MeshClipper(mesh).surface(0, 9.0)
    kept, faces, owner = MeshClipper(mesh).faces(0, 9.0)
    f = surface["n_faces"]
    assert f == len(faces) and surface["n_kept"] == kept.sum()
    assert surface["triangles"].tolist() == np.arange(3 * f).reshape(f, 3).tolist()
    np.testing.assert_array_equal(surface["vertices"], mesh.points[faces].reshape(-1, 3))
    np.testing.assert_array_equal(surface["quality"], np.repeat(mesh.quality[owner], 3))
    np.testing.assert_array_equal(surface["material"], np.repeat(mesh.material[owner], 3))


def test_nothing_kept_gives_an_empty_surface():
    mesh = MESHES["blobs"]()
    surface = MeshClipper(mesh).surface(2, 0.0, keep="below")
    assert surface["n_faces"] == 0 and surface["n_kept"] == 0
    assert surface["vertices"].shape == (0, 3) and surface["triangles"].shape == (0, 3)


def test_bad_axis_or_side_is_refused_and_the_mesh_is_not_changed():
    mesh = MESHES["noise-excluded"]()
    before = mesh.points.copy(), mesh.cells.copy()
    clipper = MeshClipper(mesh)
    with pytest.raises(ValueError, match="axis must be an integer from 0 to 2"):
        clipper.surface(3, 1.0)
    with pytest.raises(ValueError, match="axis must be an integer"):
        clip_cells(mesh.points, mesh.cells, 1.5, 1.0)
    with pytest.raises(ValueError, match="keep must be one of"):
        clipper.surface(0, 1.0, keep="left")
    clipper.surface(0, 4.0)
    np.testing.assert_array_equal(mesh.points, before[0])
    np.testing.assert_array_equal(mesh.cells, before[1])
