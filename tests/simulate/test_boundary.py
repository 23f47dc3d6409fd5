"""Boundary-value problems on the named facet groups, against closed-form solutions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate._boundary import solve_boundary_value


def bar(d: int, length: int = 8) -> np.ndarray:
    return np.ones((3, 4, length)[-d:] if d == 3 else (3, length), np.uint8)


def x_of(mesh) -> np.ndarray:
    return mesh.points[:, -1]                    # x = column = last image axis


@pytest.mark.parametrize("d", [2, 3])
def test_fixed_value_and_inward_flux_give_the_linear_profile(d):
    mesh = mesh_labels(bar(d), spacing=0.5)
    r = solve_boundary_value(mesh, {1: 4.0}, dirichlet={"xmin": 1.0}, neumann={"xmax": 2.0})
    np.testing.assert_allclose(r.potential, 1.0 + 2.0 * x_of(mesh) / 4.0, atol=1e-8)
    area = np.prod(np.asarray(bar(d).shape[:-1]) * 0.5)
    assert r.inflow["xmax"] == pytest.approx(2.0 * area)
    assert r.inflow["xmin"] == pytest.approx(-2.0 * area, rel=1e-7)
    np.testing.assert_allclose(r.flux[:, 0], -2.0, atol=1e-7)       # x component


def test_two_materials_in_series_carry_the_same_flux():
    lab = np.ones((4, 10), np.uint8)
    lab[:, 5:] = 2
    mesh = mesh_labels(lab)
    r = solve_boundary_value(mesh, {1: 1.0, 2: 4.0}, dirichlet={"xmax": 0.0},
                             neumann={"xmin": 3.0})
    x = x_of(mesh)
    # flux 3 to the right... entering at xmin means flowing towards +x: u falls with x
    expected = np.where(x <= 5, 3.0 * (5 - x) / 1.0 + 3.0 * 5 / 4.0, 3.0 * (10 - x) / 4.0)
    np.testing.assert_allclose(r.potential, expected, atol=1e-8)


@pytest.mark.parametrize("d", [2, 3])
def test_a_volume_source_gives_the_parabola_exactly_with_p2(d):
    mesh = mesh_labels(bar(d))
    k, f, length = 2.0, 1.5, 8.0
    r = solve_boundary_value(mesh, {1: k}, dirichlet={"xmin": 0.0, "xmax": 0.0},
                             source={1: f}, order=2, tol=1e-12)
    x = x_of(mesh)
    np.testing.assert_allclose(r.potential, f * x * (length - x) / (2 * k), atol=1e-8)
    assert r.source == pytest.approx(f * np.prod(bar(d).shape))
    assert r.inflow["xmin"] + r.inflow["xmax"] == pytest.approx(-r.source, rel=1e-8)


def test_robin_exchange_gives_the_film_solution():
    mesh = mesh_labels(bar(2))
    k, h, u_inf, length = 2.0, 3.0, 5.0, 8.0
    r = solve_boundary_value(mesh, {1: k}, dirichlet={"xmin": 0.0},
                             robin={"xmax": (h, u_inf)})
    slope = h * u_inf / (k + h * length)
    np.testing.assert_allclose(r.potential, slope * x_of(mesh), atol=1e-9)
    assert r.inflow["xmax"] == pytest.approx(h * (u_inf - slope * length) * 3.0)


def test_flux_into_a_void_surface_leaves_through_the_box():
    lab = np.ones((10, 10, 10), np.uint8)
    lab[3:7, 3:7, 3:7] = 0                       # an excluded cavity, 4^3 voxels
    mesh = mesh_labels(lab, exclude=(0,))
    faces = {f"{a}{e}": 0.0 for a in "xyz" for e in ("min", "max")}
    r = solve_boundary_value(mesh, {1: 1.0}, dirichlet=faces,
                             neumann={"exterior_material_1": 0.25})
    assert r.inflow["exterior_material_1"] == pytest.approx(0.25 * 6 * 16)
    assert sum(r.inflow[f] for f in faces) == pytest.approx(-0.25 * 6 * 16, rel=1e-7)
    assert r.potential.min() >= -1e-12 and r.potential.max() > 0


@pytest.mark.parametrize("kwargs, message", [
    (dict(dirichlet={"left": 0.0}), "no such boundary group; its boundary groups are xmin"),
    (dict(dirichlet={"interface_material_1_material_2": 0.0}), "interfaces lie inside"),
    (dict(dirichlet={"xmin": 0.0}, robin={"xmax": (-1.0, 0.0)}), "must be positive"),
    (dict(dirichlet={"xmin": 0.0}, neumann={"xmin": 1.0}), "xmin carries more than one"),
    (dict(neumann={"xmin": 1.0}), "no Dirichlet or Robin condition"),
    (dict(dirichlet={"xmin": 0.0}, source={7: 1.0}), "no such material"),
    (dict(robin={"xmax": 1.0}), "needs two numbers"),
])
def test_bad_conditions_say_what_to_do(kwargs, message):
    lab = np.ones((4, 6), np.uint8)
    lab[:, 3:] = 2
    with pytest.raises(ValueError, match=message):
        solve_boundary_value(mesh_labels(lab), {1: 1.0, 2: 2.0}, **kwargs)


def test_a_part_no_condition_reaches_is_refused():
    lab = np.ones((4, 9), np.uint8)
    lab[:, 4] = 0                                # an insulating wall splits the bar
    with pytest.raises(ValueError, match="are not connected to the Dirichlet and Robin groups"):
        solve_boundary_value(mesh_labels(lab, exclude=(0,)), {1: 1.0},
                             dirichlet={"xmin": 0.0}, neumann={"xmax": 1.0})


def test_command_line_writes_the_field(tmp_path, capsys):
    np.save(tmp_path / "lab.npy", bar(2))
    code = main(["simulate", str(tmp_path / "lab.npy"), "-k", "1=2", "--dirichlet", "xmin=0",
                 "--robin", "xmax=3:5", "-o", str(tmp_path / "f.vtu"), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0
    assert report["inflow"]["xmax"] == pytest.approx(-report["inflow"]["xmin"], rel=1e-7)
    import meshio

    m = meshio.read(tmp_path / "f.vtu")
    assert "potential" in m.point_data and "flux" in m.cell_data
    code = main(["simulate", str(tmp_path / "lab.npy"), "-k", "1=2", "--robin", "xmax=3"])
    assert code == 2 and "GROUP=H:UINF" in capsys.readouterr().err
