"""The periodic-fluctuation protocol and periodic meshes, against exact answers.

* Laminates: the arithmetic mean along the layers, the harmonic mean across, exactly.
* A homogeneous anisotropic material: its own tensor, off-diagonal terms included.
* The checkerboard: sqrt(k1 k2) exactly (Dykhne), approached as the interfaces are refined.
* Symmetry and the image's own symmetries: transposing the image transposes the tensor.
* Periodic meshes: opposite box faces carry the same facets, translated.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from simulate_cases import checkerboard

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.mesh.checks._facets import facet_groups
from napari_swa_imesh.simulate import simulate


def layers(d: int, axis: int, n: int = 8) -> np.ndarray:
    lab = np.ones((n,) * d, np.uint8)
    index = [slice(None)] * d
    index[axis] = slice(n // 2, None)
    lab[tuple(index)] = 2
    return lab


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("order", [1, 2])
def test_laminates_give_the_arithmetic_and_harmonic_means_exactly(d, order):
    k = {1: 1.0, 2: 3.0}
    for axis in range(d):
        r = simulate(layers(d, axis), k, order=order, protocol="periodic", tol=1e-12)
        across = "xyz"[d - 1 - axis]
        expected = np.full(d, 2.0)                       # along the layers: (1 + 3) / 2
        expected[d - 1 - axis] = 1.5                     # across: 2 / (1 + 1/3)
        np.testing.assert_allclose(np.diag(r.tensor), expected, rtol=1e-8)
        np.testing.assert_allclose(r.tensor - np.diag(np.diag(r.tensor)), 0, atol=1e-8)
        assert r.k_eff[across] == pytest.approx(1.5, rel=1e-8)


@pytest.mark.parametrize("d", [2, 3])
def test_a_homogeneous_anisotropic_material_gives_its_own_tensor(d):
    rng = np.random.default_rng(d)
    q, _ = np.linalg.qr(rng.standard_normal((d, d)))
    tensor = q @ np.diag(rng.uniform(0.5, 5.0, d)) @ q.T
    r = simulate(np.ones((5, 6, 4)[:d], np.uint8), {1: tensor}, protocol="periodic",
                 spacing=(1.0, 0.7, 1.3)[:d], tol=1e-12, order=1)
    np.testing.assert_allclose(r.tensor, tensor, rtol=1e-8, atol=1e-10)


def test_refinement_converges_to_the_checkerboard_value():
    exact = np.sqrt(10.0)
    errors = []
    for refine in (1, 2, 3):
        r = simulate(checkerboard(4, 4), {1: 1.0, 2: 10.0}, protocol="periodic",
                     refine=refine)
        assert r.tensor[0, 0] == pytest.approx(r.tensor[1, 1], rel=1e-9)   # board symmetry
        errors.append(r.tensor[0, 0] / exact - 1)
    assert all(e > 0 for e in errors) and errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.05


def test_transposing_the_image_transposes_the_tensor():
    rng = np.random.default_rng(5)
    lab = (rng.random((10, 7)) < 0.4).astype(np.uint8) + 1
    k = {1: 1.0, 2: 7.0}
    a = simulate(lab, k, protocol="periodic", tol=1e-12).tensor
    b = simulate(lab.T.copy(), k, protocol="periodic", tol=1e-12).tensor
    np.testing.assert_allclose(a, a.T, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(b, a[::-1, ::-1], rtol=1e-7, atol=1e-9)
    # the periodic and mixed answers both lie within the Voigt-Reuss bounds
    mixed = simulate(lab, k, tol=1e-12)
    for name, (lo, hi) in mixed.bounds.items():
        assert lo <= mixed.k_eff[name] <= hi


@pytest.mark.parametrize(("d", "shape", "spacing", "rule"), [
    (2, (9, 6), (1.0, 2.5), "lowest"),
    (3, (9, 6, 7), (1.0, 2.5, 1.0), "lowest"),   # odd extents: Kuhn's lowest-corner rule
    (3, (8, 6, 10), (1.0, 1.0, 1.0), "parity"),  # even extents: five tetrahedra per plain leaf
])
def test_periodic_meshes_have_matching_opposite_faces(d, shape, spacing, rule):
    rng = np.random.default_rng(d)
    lab = rng.integers(1, 4, size=shape).astype(np.uint8)
    lab[(slice(2, 5),) * d] = 1
    mesh = mesh_labels(lab, periodic=True, spacing=spacing)
    assert mesh.recipe.diagonal_rule == rule
    groups = facet_groups(mesh)
    lo, hi = mesh.image_box()
    for name, axis in zip("xyz"[:d], range(d - 1, -1, -1)):
        def facet_set(group, shift, axis=axis):
            corners = mesh.points[group.facets].copy()
            corners[:, :, axis] -= shift
            keys = np.round(corners * 1e6).astype(np.int64)
            keys = np.sort(keys.view([("", np.int64)] * d).reshape(len(keys), d), axis=1)
            return {tuple(row.tolist()) for row in keys}
        low, high = groups[f"{name}min"], groups[f"{name}max"]
        assert len(low) == len(high)
        assert facet_set(low, lo[axis]) == facet_set(high, hi[axis])
    plain = mesh_labels(lab, spacing=spacing)
    assert mesh.n_cells >= plain.n_cells


def test_a_mesh_without_matching_faces_is_refused():
    lab = np.ones((16, 16), np.uint8)
    lab[0:8, 0:3] = 2                           # on the xmin side only, coarse leaves elsewhere
    with pytest.raises(ValueError, match="the mesh is not periodic"):
        simulate(mesh_labels(lab), {1: 1.0, 2: 2.0}, protocol="periodic")
    with pytest.raises(ValueError, match="protocol must be one of mixed, periodic"):
        simulate(lab, {1: 1.0, 2: 2.0}, protocol="bloch")


@pytest.mark.parametrize("order", [1, 2])
def test_opposite_faces_cut_differently_are_refused_though_their_nodes_match(order,
                                                                            monkeypatch):
    """Five-tetrahedra leaves (the parity rule) forced on an odd-size periodic box: every
    node, and at second order every mid-edge node (crossing face diagonals meet at the
    face centre), has its twin on the opposite face, but the facets there differ."""
    from napari_swa_imesh.mesh.mesher import _imesh

    lab = np.random.default_rng(3).integers(1, 3, size=(5, 6, 7)).astype(np.uint8)
    real = _imesh.template_mesh
    monkeypatch.setattr(_imesh, "template_mesh",
                        lambda bal, meshed, rule: real(bal, meshed, rule="parity"))
    mesh = mesh_labels(lab, periodic=True)
    with pytest.raises(ValueError, match="are cut into different facets"):
        simulate(mesh, {1: 1.0, 2: 10.0}, protocol="periodic", order=order)
    monkeypatch.undo()
    honest = mesh_labels(lab, periodic=True)
    assert honest.recipe.diagonal_rule == "lowest"
    assert simulate(honest, {1: 1.0, 2: 10.0}, protocol="periodic", order=order,
                    adapt=0).tensor is not None


def test_command_line_prints_the_tensor(tmp_path, capsys):
    np.save(tmp_path / "lab.npy", layers(2, 1))
    code = main(["simulate", str(tmp_path / "lab.npy"), "-k", "1=1", "2=3",
                 "--protocol", "periodic", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["protocol"] == "periodic"
    np.testing.assert_allclose(report["tensor"], [[1.5, 0], [0, 2]], atol=1e-8)
    code = main(["simulate", str(tmp_path / "lab.npy"), "-k", "1=1", "2=3",
                 "--protocol", "periodic", "--axes", "x", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert report["tensor"][1][1] is None and report["tensor"][0][0] == pytest.approx(1.5)
