"""Named facet groups: a partition of the boundary and the interfaces, oriented outward."""

import numpy as np
import pytest

from napari_swa_imesh.mesh import facet_groups, mesh_labels


def _brute_force(cells, material):
    """Boundary facets and material-interface facets, by counting (small meshes)."""
    owners = {}
    d = cells.shape[1] - 1
    for i, cell in enumerate(cells.tolist()):
        for k in range(d + 1):
            owners.setdefault(tuple(sorted(cell[:k] + cell[k + 1:])), []).append(i)
    boundary = {f for f, o in owners.items() if len(o) == 1}
    interface = {f for f, o in owners.items() if len(o) == 2 and material[o[0]] != material[o[1]]}
    return boundary, interface


def _normals(points, facets):
    p = points[facets]                                        # (F, d, d)
    if facets.shape[1] == 2:
        d = p[:, 1] - p[:, 0]
        return np.stack([d[:, 1], -d[:, 0]], axis=1)
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


@pytest.mark.parametrize("shape, seed", [((9, 11), 0), ((6, 7, 5), 1), ((5, 6, 7), 2)])
def test_groups_partition_the_boundary_and_the_interfaces(shape, seed):
    labels = np.random.default_rng(seed).integers(0, 4, shape)
    mesh = mesh_labels(labels, exclude=[0], spacing=np.linspace(1, 2, len(shape)),
                       material_names={2: "bone"})
    groups = facet_groups(mesh)
    boundary, interface = _brute_force(mesh.cells, mesh.material)
    seen = [tuple(sorted(f)) for g in groups.values() for f in g.facets.tolist()]
    assert len(seen) == len(set(seen))                       # each facet once
    assert set(seen) == boundary | interface                 # and every one of them
    d = len(shape)
    sides = {f"{a}{e}" for a in "xyz"[:d] for e in ("min", "max")}
    assert sides <= set(groups)
    for name, group in groups.items():
        facets = {tuple(sorted(f)) for f in group.facets.tolist()}
        assert facets <= (interface if name.startswith("interface_") else boundary), name
        # the owner holds the facet, and the facet points out of it
        cells = mesh.cells[group.owner]
        opposite = cells[np.arange(len(cells)), group.opposite]
        assert not (group.facets == opposite[:, None]).any()       # the corner off the facet
        rest = np.sort(np.where(np.arange(d + 1) == group.opposite[:, None], -1, cells),
                       axis=1)[:, 1:]
        np.testing.assert_array_equal(rest, np.sort(group.facets, axis=1))
        centroid = mesh.points[cells].mean(axis=1)
        inward = np.einsum("fi,fi->f", _normals(mesh.points, group.facets),
                           centroid - mesh.points[group.facets[:, 0]])
        assert np.all(inward < 0), name
    assert any(n.startswith("interface_bone_") or n.endswith("_bone") for n in groups)
    assert "interface_material_1_bone" in groups               # lower label first


def test_box_sides_cover_the_faces_of_the_image():
    labels = np.random.default_rng(3).integers(1, 3, (4, 5, 6))
    spacing = (2.0, 1.0, 0.5)
    mesh = mesh_labels(labels, spacing=spacing)
    groups = facet_groups(mesh)
    assert not any(n.startswith("exterior_") for n in groups)
    extent = np.array(labels.shape) * spacing                  # (plane, row, column)
    for name, axis in (("x", 2), ("y", 1), ("z", 0)):
        for end in ("min", "max"):
            p = mesh.points[groups[name + end].facets]
            area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]),
                                        axis=1).sum()
            assert area == pytest.approx(np.prod(np.delete(extent, axis)))
            coordinate = p[..., axis]
            assert np.allclose(coordinate, 0 if end == "min" else extent[axis])


@pytest.mark.parametrize("passes", ["one", "many", "ranked"])
@pytest.mark.parametrize("shape", [(9, 11), (6, 7, 5)])
def test_paired_facets_match_counting_in_every_pass_plan(monkeypatch, shape, passes):
    """One facet sort, whatever the passes: the pairs a dictionary of sorted ids gives,
    lowest element first, facets in the order of their sorted ids."""
    from napari_swa_imesh.mesh.checks import _facets
    from napari_swa_imesh.mesh.checks._facets import FACE_CORNERS, paired_facets

    rng = np.random.default_rng(len(shape))
    mesh = mesh_labels(rng.integers(0, 4, shape), exclude=[0])
    # scattered ids (wide keys), and three elements on one facet
    cells = rng.permutation(len(mesh.points))[mesh.cells]
    cells = np.concatenate([cells, cells[:3], cells[:1]])
    if passes != "one":
        monkeypatch.setattr(_facets, "_KEYS_PER_PASS", 40)
    if passes == "ranked":
        monkeypatch.setattr(_facets, "_MAX_PASSES", 1)
    facets, owners, opposite = paired_facets(cells)
    d = cells.shape[1] - 1
    seen = {}
    for i, cell in enumerate(cells.tolist()):
        for k in range(d + 1):
            seen.setdefault(tuple(sorted(cell[:k] + cell[k + 1:])), []).append((i, k))
    expected = sorted(seen)
    assert [tuple(sorted(f)) for f in facets.tolist()] == expected
    for f, own, opp in zip(expected, owners.tolist(), opposite.tolist()):
        pairs = seen[f]
        assert own[0] == pairs[0][0] and opp[0] == pairs[0][1]
        assert own[1:] == ([pairs[1][0]] if len(pairs) == 2 else [-1])
    np.testing.assert_array_equal(facets,
                                  cells[owners[:, 0, None], FACE_CORNERS[d][opposite[:, 0]]])
