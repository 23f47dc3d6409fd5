"""Steady diffusion and k_eff: analytic references, invariances, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import conductivity_tensors, parse_conductivity_args, simulate


def _layers(shape, axis, cuts, rng):
    """Labels 1..n in layers normal to image `axis` (plane/row/column index)."""
    edges = np.sort(rng.choice(np.arange(1, shape[axis]), size=cuts, replace=False))
    index = np.arange(shape[axis])
    layer = np.searchsorted(edges, index, side="right") + 1
    view = [1] * len(shape)
    view[axis] = shape[axis]
    return np.broadcast_to(layer.reshape(view), shape).astype(np.uint8)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("shape", [(9, 14), (7, 6, 10)])
def test_laminates_give_the_harmonic_and_arithmetic_means(shape, order):
    rng = np.random.default_rng(len(shape) * 10 + order)
    ndim = len(shape)
    names = ("z", "y", "x")[-ndim:]
    spacing = rng.uniform(0.5, 2.0, ndim)
    for axis in range(ndim):
        labels = _layers(shape, axis, 3, rng)
        k = {m: float(rng.uniform(0.1, 10)) for m in range(1, 5)}
        r = simulate(labels, k, spacing=spacing, order=order)
        thickness = np.bincount(labels.reshape(-1), minlength=5)[1:] / labels.size
        kv = np.array([k[m] for m in range(1, 5)])
        harmonic = 1 / np.sum(thickness / kv)
        arithmetic = np.sum(thickness * kv)
        for a, name in enumerate(names):
            expected = harmonic if a == axis else arithmetic
            assert r.k_eff[name] == pytest.approx(expected, rel=1e-8), (axis, name)
            lo, hi = r.bounds[name]
            assert lo == pytest.approx(harmonic) and hi == pytest.approx(arithmetic)


def test_diagonal_tensors_follow_the_x_y_z_frame():
    labels = np.ones((5, 6, 7), dtype=np.uint8)
    labels[0, 0, 0] = 2                                  # keeps the mesh from one leaf
    r = simulate(labels, {1: [1.0, 2.0, 3.0], 2: [1.0, 2.0, 3.0]}, order=1)
    assert r.k_eff["x"] == pytest.approx(1.0, rel=1e-9)
    assert r.k_eff["y"] == pytest.approx(2.0, rel=1e-9)
    assert r.k_eff["z"] == pytest.approx(3.0, rel=1e-9)
    # the same tensor, given in full
    t = np.diag([1.0, 2.0, 3.0])
    r2 = simulate(labels, {1: t, 2: t}, axes=["y"])
    assert r2.k_eff == {"y": pytest.approx(2.0, rel=1e-9)}


def _blobs(shape, seed, materials=3):
    from scipy import ndimage

    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), 2)
    q = np.quantile(f, np.linspace(0, 1, materials + 1)[1:-1])
    return (np.digitize(f, q) + 1).astype(np.uint8)


@pytest.mark.parametrize("shape", [(24, 30), (10, 12, 14)])
def test_k_eff_is_invariant_under_relabelling_scaling_and_transposition(shape):
    labels = _blobs(shape, 3)
    k = {1: 1.0, 2: 10.0, 3: 0.1}
    base = simulate(labels, k, order=1, adapt=0)
    # relabel materials (and their conductivities) by a permutation
    perm = {1: 7, 2: 3, 3: 5}
    relabelled = np.vectorize(perm.get)(labels).astype(np.uint8)
    r = simulate(relabelled, {perm[m]: v for m, v in k.items()}, order=1, adapt=0)
    for a in base.k_eff:
        assert r.k_eff[a] == pytest.approx(base.k_eff[a], rel=1e-8)
    # conductivities times c: k_eff times c; spacing times s: unchanged
    r = simulate(labels, {m: 4.0 * v for m, v in k.items()}, spacing=3.0, order=1, adapt=0)
    for a in base.k_eff:
        assert r.k_eff[a] == pytest.approx(4.0 * base.k_eff[a], rel=1e-8)
    # reversing the image axes swaps the axis names
    names = list(base.k_eff)                              # x, y(, z)
    r = simulate(np.ascontiguousarray(labels.T), k, order=1, adapt=0)
    for a, b in zip(names, names[::-1]):
        assert r.k_eff[a] == pytest.approx(base.k_eff[b], rel=1e-8)


def test_p2_refines_k_eff_of_a_two_phase_image_towards_the_finer_mesh():
    labels = _blobs((20, 20), 5, materials=2)
    k = {1: 1.0, 2: 20.0}
    # a finer mesh needs finer leaves: split each material by a voxel checkerboard
    up = np.kron(labels, np.ones((4, 4), np.uint8))
    parity = np.indices(up.shape).sum(axis=0) % 2
    fine_labels = ((up - 1) * 2 + parity + 1).astype(np.uint8)
    fine_k = {1: 1.0, 2: 1.0, 3: 20.0, 4: 20.0}
    fine = simulate(fine_labels, fine_k, spacing=0.25, order=2, axes="x").k_eff["x"]
    p1 = simulate(labels, k, axes="x", order=1, adapt=0).k_eff["x"]
    p2 = simulate(labels, k, axes="x", order=2, adapt=0).k_eff["x"]
    # both conforming, both above the exact value; P2 is closer
    assert fine < p2 < p1


def test_volume_fractions_and_excluded_voids():
    labels = _blobs((16, 18), 7, materials=2) + 1          # 2 and 3 ...
    labels[3:6, 3:6] = 1                                    # ... around pores of 1
    labels[10:13, 8:12] = 1
    r = simulate(labels, {1: 1.0, 2: 2.0, 3: 3.0})
    counts = np.bincount(labels.reshape(-1))[1:] / labels.size
    assert np.allclose(list(r.volume_fractions.values()), counts)
    assert _connected(labels)
    void = simulate(labels, {2: 2.0, 3: 3.0}, exclude=[1])
    assert void.bounds["x"][0] == 0.0                # a void makes the harmonic mean 0
    assert 0 < void.k_eff["x"] < r.k_eff["x"]
    assert sum(void.volume_fractions.values()) == pytest.approx(1 - counts[0])


def _connected(labels):
    from scipy import ndimage

    return ndimage.label(labels != 1)[1] == 1


def test_result_summary_and_describe():
    labels = _blobs((12, 12), 1)
    r = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1}, material_names={1: "bone"}, order=1)
    s = r.summary()
    assert set(s["k_eff"]) == {"x", "y"} and s["dofs"] == len(r.mesh.points)
    assert s["residual"] < 1e-9
    text = r.describe()
    assert "k_eff x" in text and "bone" in text
    assert r.potential["x"].shape == (len(r.mesh.points),)
    assert r.flux["x"].shape == (r.mesh.n_cells, 2)
    # the potential runs from 0 on xmin to 1 on xmax
    x = r.mesh.points[:, 1]
    assert np.allclose(r.potential["x"][x == 0], 0) and np.allclose(r.potential["x"][x == 12], 1)


def test_a_floating_island_is_refused():
    labels = np.full((12, 12), 2, dtype=np.uint8)
    labels[3:9, 3:9] = 1
    labels[5:7, 5:7] = 3                     # material 3 floats inside excluded 1
    with pytest.raises(ValueError, match="not connected to the x faces"):
        simulate(labels, {2: 1.0, 3: 1.0}, exclude=[1])


@pytest.mark.parametrize("conductivity, message", [
    ({1: 1.0}, "material 2 has no conductivity"),
    ({1: 1.0, 2: 0.0}, "must be positive"),
    ({1: 1.0, 2: -3.0}, "must be positive"),
    ({1: 1.0, 2: float("nan")}, "not finite"),
    ({1: 1.0, 2: float("inf")}, "not finite"),
    ({1: 1.0, 2: True}, "must be a number"),
    ({1: 1.0, 2: [1.0, 2.0, 3.0]}, "got shape"),
    ({1: 1.0, 2: [[1.0, 2.0], [0.0, 1.0]]}, "symmetric"),
    ({1: 1.0, 2: 1.0, 9: 1.0}, "not in the mesh"),
    ({1: 1.0, 2: 1.0, "steel": 1.0}, "not in the mesh"),
    ({}, "every material"),
])
def test_bad_conductivities_are_refused(conductivity, message):
    labels = np.ones((6, 6), dtype=np.uint8)
    labels[:, 3:] = 2
    with pytest.raises(ValueError, match=message):
        simulate(labels, conductivity)


def test_bad_options_are_refused():
    labels = np.ones((6, 6), dtype=np.uint8)
    labels[:, 3:] = 2
    k = {1: 1.0, 2: 2.0}
    with pytest.raises(ValueError, match="order must be 1 or 2"):
        simulate(labels, k, order=3)
    with pytest.raises(ValueError, match="axes must be"):
        simulate(labels, k, axes="z")
    with pytest.raises(ValueError, match="a mesh already"):
        simulate(mesh_labels(labels), k, spacing=2.0)


def test_materials_by_name_and_the_command_line_parser():
    labels = np.ones((6, 6), dtype=np.uint8)
    labels[:, 3:] = 2
    mesh = mesh_labels(labels, material_names={1: "soft", 2: "hard"})
    r = simulate(mesh, {"soft": 1.0, "hard": 3.0}, axes="x")
    assert r.k_eff["x"] == pytest.approx(1.5)
    parsed = parse_conductivity_args(["soft=1", "2=0.5,0.25", "3=1,0,0,2"])
    assert parsed == {"soft": 1.0, "2": [0.5, 0.25], "3": [[1.0, 0.0], [0.0, 2.0]]}
    t = conductivity_tensors({1: [0.5, 0.25]}, [1], 2)   # x=0.5 is the column axis
    assert np.allclose(t[0], np.diag([0.25, 0.5]))
    for bad in (["1"], ["=2"], ["1=a"], ["1=1", "1=2"]):
        with pytest.raises(ValueError, match="--conductivity"):
            parse_conductivity_args(bad)


@pytest.mark.parametrize("order, rate", [(1, 2.0), (2, 3.0)])
def test_manufactured_solution_converges_at_the_expected_rate(order, rate):
    """-div(grad u) = f on the unit square with u = sin(pi x) sin(pi y), u = 0 on the
    boundary, on IMESH meshes of a checkerboard (every voxel a leaf): L2 error rate."""
    import skfem

    from napari_swa_imesh.simulate._assembly import fe_space, stiffness_matrix
    from napari_swa_imesh.simulate._fe import fe_basis
    from napari_swa_imesh.simulate._solve import solve_dirichlet

    def exact(x):
        return np.sin(np.pi * x[0]) * np.sin(np.pi * x[1])

    @skfem.LinearForm
    def source(v, w):
        return 2 * np.pi ** 2 * exact(w.x) * v

    @skfem.Functional
    def l2(w):
        return (w["u"] - exact(w.x)) ** 2

    errors = []
    sizes = (8, 16, 32)
    for n in sizes:
        labels = (np.indices((n, n)).sum(axis=0) % 2 + 1).astype(np.uint8)
        mesh = mesh_labels(labels, spacing=1.0 / n)
        basis = fe_basis(mesh, order)
        tensors = np.stack([np.eye(2), np.eye(2)])
        cell_material = np.searchsorted([1, 2], mesh.material)
        matrix = stiffness_matrix(fe_space(mesh, order), tensors, cell_material)
        quad = skfem.Basis(basis.mesh, basis.elem, intorder=2 * order + 2)
        rhs = skfem.asm(source, quad)
        fixed = basis.get_dofs().all()
        u, info = solve_dirichlet(matrix, fixed, np.zeros(fixed.size), rhs, tol=1e-12)
        errors.append(np.sqrt(l2.assemble(quad, u=quad.interpolate(u))))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert rates.min() > rate - 0.2, (errors, rates)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("low, high", [(1e-6, 1e6), (1e6, 1e-6), (1e-8, 1e8), (1e8, 1e-8)])
def test_extreme_contrast_laminates_are_exact_or_refused(low, high, order):
    """Contrast 1e12 is solved exactly; at 1e16 (beyond float64) the answer is exact or
    refused with the sentence, never silently wrong."""
    labels = np.ones((6, 5, 8), dtype=np.uint8)
    labels[:, :, 4:] = 2
    try:
        r = simulate(labels, {1: low, 2: high}, order=order)
    except ValueError as exc:
        assert high / low > 1e12 or low / high > 1e12
        assert "did not converge far enough" in str(exc)
        return
    assert r.k_eff["x"] == pytest.approx(2 / (1 / low + 1 / high), rel=1e-6)
    assert r.k_eff["y"] == pytest.approx((low + high) / 2, rel=1e-6)


def test_runs_are_repeatable_to_the_last_digit():
    labels = _blobs((10, 11, 12), 9)
    k = {1: 1e-3, 2: 1.0, 3: 1e3}
    assert simulate(labels, k).k_eff == simulate(labels, k).k_eff


def test_a_part_floating_along_the_second_axis_only_is_refused():
    labels = np.full((10, 12), 2, dtype=np.uint8)
    labels[3:7, :] = 1                               # excluded band across the image ...
    labels[4:6, :] = 3                               # ... around a bar of 3 spanning x
    # along x the bar touches both faces; along y it floats between the excluded band
    r = simulate(labels, {2: 1.0, 3: 1.0}, exclude=[1], axes="x")
    assert r.k_eff["x"] > 0
    for axes in ("xy", "yx"):
        with pytest.raises(ValueError, match="material 3.*not connected to the y faces"):
            simulate(labels, {2: 1.0, 3: 1.0}, exclude=[1], axes=axes)


def test_a_given_mesh_is_not_modified():
    labels = np.ones((6, 6), dtype=np.uint8)
    labels[:, 3:] = 2
    mesh = mesh_labels(labels)
    simulate(mesh, {"a": 1.0, "b": 2.0}, material_names={1: "a", 2: "b"})
    assert mesh.material_names == {}


@pytest.mark.parametrize("suffix", [".vtu", ".xdmf"])
def test_fields_are_written_with_the_mesh_in_both_formats(tmp_path, suffix):
    import meshio

    from napari_swa_imesh.simulate import write_field

    labels = _blobs((10, 12), 4)
    r = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.1})
    written = write_field(r, tmp_path / f"field{suffix}")
    m = meshio.read(written[0])
    np.testing.assert_allclose(m.point_data["potential_y"], r.potential["y"])
    np.testing.assert_allclose(m.cell_data["flux_x"][0], r.flux["x"])
    np.testing.assert_array_equal(m.cell_data["material"][0], r.mesh.material)
