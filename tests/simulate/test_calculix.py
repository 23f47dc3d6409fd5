"""CalculiX solves heat conduction on our .inp with the facet groups we write, and agrees.

* a potential 0/1 on the node sets ``xmin``/``xmax``: the heat flow CalculiX reports gives
  the k_eff :func:`simulate` computes on the same mesh (both linear tetrahedra);
* a flux on the element faces of the surface ``xmax``: all of it leaves through ``xmin``,
  which holds only if every face number of the surface is right.
"""

import re
import shutil
import subprocess

import numpy as np
import pytest
from scipy import ndimage

from napari_swa_imesh.mesh import mesh_labels, write_mesh
from napari_swa_imesh.simulate import simulate

pytestmark = pytest.mark.skipif(shutil.which("ccx") is None,
                                reason="CalculiX (ccx) is not installed")

MATERIALS = """*INCLUDE, INPUT=mesh.inp
*MATERIAL, NAME=A
*CONDUCTIVITY
1.
*MATERIAL, NAME=B
*CONDUCTIVITY
10.
*SOLID SECTION, ELSET={a}, MATERIAL=A
*SOLID SECTION, ELSET={b}, MATERIAL=B
*STEP
*HEAT TRANSFER, STEADY STATE
"""


def _mesh(shape, seed):
    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), 1.2)
    labels = (f > 0).astype(np.uint8) + 1
    return mesh_labels(labels, spacing=(1.5,) + (1.0,) * (len(shape) - 1),
                       material_names={1: "soft", 2: "hard"})


def _run(tmp_path, deck: str) -> str:
    (tmp_path / "job.inp").write_text(deck)
    result = subprocess.run(["ccx", "job"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120)
    assert "ERROR" not in result.stdout and "Job finished" in result.stdout, result.stdout
    return (tmp_path / "job.dat").read_text()


def _total(dat: str) -> float:
    return float(re.search(r"total heat generation for set \w+.*\n\s*\n\s*(\S+)", dat).group(1))


def test_k_eff_from_calculix_equals_ours(tmp_path):
    mesh = _mesh((6, 7, 8), 5)
    write_mesh(mesh, tmp_path / "mesh.inp", abaqus_elements="heat")
    dat = _run(tmp_path, MATERIALS.format(a="soft", b="hard") + """*BOUNDARY
xmin, 11, 11, 0.
xmax, 11, 11, 1.
*NODE PRINT, NSET=xmax, TOTALS=ONLY
RFL
*END STEP
""")
    length, area = 8 * 1.0, (6 * 1.5) * (7 * 1.0)
    ours = simulate(mesh, {"soft": 1.0, "hard": 10.0}, axes="x", order=1).k_eff["x"]
    assert _total(dat) * length / area == pytest.approx(ours, rel=1e-6)


@pytest.mark.parametrize("shape", [(6, 7, 8), (5, 9, 4)])
def test_a_flux_on_the_xmax_surface_leaves_through_xmin(tmp_path, shape):
    """(3-D only: CalculiX has no 2-D heat element; it reads DC2D3 as unknown.)"""
    mesh = _mesh(shape, 7)
    write_mesh(mesh, tmp_path / "mesh.inp", abaqus_elements="heat")
    text = (tmp_path / "mesh.inp").read_text()
    surface = re.search(r"\*SURFACE, NAME=xmax, TYPE=ELEMENT\n((?:[^*].*\n)+)", text).group(1)
    dflux = "".join(f"{line.strip()}, 2.\n" for line in surface.splitlines())
    dat = _run(tmp_path, MATERIALS.format(a="soft", b="hard")
               + f"*BOUNDARY\nxmin, 11, 11, 0.\n*DFLUX\n{dflux}"
               + "*NODE PRINT, NSET=xmin, TOTALS=ONLY\nRFL\n*END STEP\n")
    extent = np.array(shape, float) * (1.5, 1.0, 1.0)
    area = np.prod(extent[:-1])                         # the face normal to x (columns)
    assert _total(dat) == pytest.approx(-2.0 * area, rel=1e-9)


@pytest.mark.parametrize("elements", ["heat", "mechanical"])
def test_k_eff_from_calculix_on_ten_node_tetrahedra_equals_ours(tmp_path, elements):
    """Second order: DC3D10 (or C3D10, which CalculiX also runs in a heat step) with the
    mid-edge nodes in the xmin/xmax node sets, against our P2 solution on the same mesh."""
    mesh = _mesh((6, 7, 8), 5)
    write_mesh(mesh, tmp_path / "mesh.inp", abaqus_elements=elements, order=2)
    kind = "DC3D10" if elements == "heat" else "C3D10"
    assert f"*ELEMENT, TYPE={kind}\n" in (tmp_path / "mesh.inp").read_text()
    dat = _run(tmp_path, MATERIALS.format(a="soft", b="hard") + """*BOUNDARY
xmin, 11, 11, 0.
xmax, 11, 11, 1.
*NODE PRINT, NSET=xmax, TOTALS=ONLY
RFL
*END STEP
""")
    length, area = 8 * 1.0, (6 * 1.5) * (7 * 1.0)
    ours = simulate(mesh, {"soft": 1.0, "hard": 10.0}, axes="x", order=2).k_eff["x"]
    linear = simulate(mesh, {"soft": 1.0, "hard": 10.0}, axes="x", order=1).k_eff["x"]
    assert _total(dat) * length / area == pytest.approx(ours, rel=1e-6)
    assert abs(ours - linear) > 1e-4 * ours          # a second-order answer, not the linear
