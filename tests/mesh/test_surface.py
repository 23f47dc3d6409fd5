"""Face extraction for display: pure numpy, tested headless (moved out of _napari)."""

import itertools

import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels, mesh_surface, shown_faces


def _faces_by_counting(cells, material):
    """Sorted faces seen once, or between two materials: the definition, by brute force."""
    seen = {}
    for i, tet in enumerate(cells.tolist()):
        for face in itertools.combinations(sorted(tet), 3):
            seen.setdefault(face, []).append(i)
    return {f for f, o in seen.items() if len(o) == 1 or material[o[0]] != material[o[1]]}


@pytest.mark.parametrize("exclude", [(), (2,)])
def test_3d_faces_are_boundary_and_interfaces_once_each(exclude):
    rng = np.random.default_rng(7)
    mesh = mesh_labels(rng.integers(1, 4, (5, 4, 6)), exclude=exclude)
    faces, owners = shown_faces(mesh.cells, mesh.material)
    keys = [tuple(sorted(f)) for f in faces.tolist()]
    assert len(set(keys)) == len(keys)
    assert set(keys) == _faces_by_counting(mesh.cells, mesh.material)
    boundary = owners[:, 1] < 0
    assert (mesh.material[owners[~boundary, 0]] != mesh.material[owners[~boundary, 1]]).all()


def test_surface_values_are_the_worse_owner_and_the_first_material():
    rng = np.random.default_rng(3)
    mesh = mesh_labels(rng.integers(1, 3, (4, 4, 4)), spacing=(3.0, 1.0, 1.0))
    faces, owners = shown_faces(mesh.cells, mesh.material)
    surface = mesh_surface(mesh)
    q = mesh.quality
    worst = np.where(owners[:, 1] >= 0, np.maximum(q[owners[:, 0]], q[owners[:, 1]]),
                     q[owners[:, 0]])
    np.testing.assert_array_equal(surface["quality"], np.repeat(worst, 3))
    np.testing.assert_array_equal(surface["material"], np.repeat(mesh.material[owners[:, 0]], 3))
    np.testing.assert_array_equal(surface["vertices"], mesh.points[faces].reshape(-1, 3))
    assert surface["n_faces"] == len(faces) == len(surface["triangles"])
