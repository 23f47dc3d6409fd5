"""Meshes of the standard cases are byte-identical across refactors (issue 24).

Each case meshes a small seeded label image through the public library and hashes the
element and vertex arrays (dtype, shape and bytes) and every file that ``write_mesh``
writes. The constants below were computed on the code before the issue-24 moves; a change
to any of them means the mesher or a writer changed its output, which a structural
refactor must not do. To regenerate after an intended change of output (never for a
move): ``python tests/test_mesh_hashes.py`` prints the table.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "mesh"))
from imesh_cases import blobs, thin  # noqa: E402

from napari_swa_imesh.mesh import mesh_labels, write_mesh  # noqa: E402


def _labels_2d() -> np.ndarray:
    return blobs((23, 37), 3, seed=1)


def _labels_3d() -> np.ndarray:
    return blobs((11, 14, 9), 3, seed=2)


CASES = {
    "2d": lambda: mesh_labels(_labels_2d()),
    "2d-refine2": lambda: mesh_labels(_labels_2d(), refine=2),
    "2d-delaunay": lambda: mesh_labels(_labels_2d(), method="delaunay"),
    "2d-exclude0-maxsize": lambda: mesh_labels(_labels_2d(), exclude=(0,), max_size=4.0),
    "3d": lambda: mesh_labels(_labels_3d()),
    "3d-refine1": lambda: mesh_labels(_labels_3d(), refine=1),
    "3d-aniso": lambda: mesh_labels(_labels_3d(), spacing=(1.0, 0.5, 2.0)),
    "3d-thin-exclude0": lambda: mesh_labels(thin((8, 8, 8), seed=30), exclude=(0,)),
}

FILE_CASES = {           # (mesh case, file name, write_mesh options)
    "2d.vtu": ("2d", "m.vtu", {}),
    "2d.msh": ("2d", "m.msh", {}),
    "3d.vtu": ("3d", "m.vtu", {}),
    "3d.msh": ("3d", "m.msh", {}),
    "3d-ascii.msh": ("3d", "m.msh", {"binary": False}),
    "3d.inp": ("3d", "m.inp", {}),
    "3d-order2.inp": ("3d", "m.inp", {"order": 2, "abaqus_elements": "heat"}),
    "3d-aniso.node": ("3d-aniso", "m.node", {}),
    "2d-refine2.vtk": ("2d-refine2", "m.vtk", {}),
}


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def mesh_digest(name: str) -> str:
    m = CASES[name]()
    return _digest(m.points, m.cells, m.material)


def file_digests(name: str, folder: Path) -> dict[str, str]:
    case, file, options = FILE_CASES[name]
    out = folder / name
    out.mkdir()
    written = write_mesh(CASES[case](), out / file, **options)
    return {Path(p).name: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in written}


MESH_HASHES = {
    "2d": "84d126d45a76467c55bd1870cd16856b9e5cc9efe3ebdb25a2a271f809849229",
    "2d-delaunay": "785d729852a28d61a377ad9df8b1e63c2c20459afdd0da3266976893b92b881c",
    "2d-exclude0-maxsize": "8537f32f00d473fef1a96a78f3a5c9bb49eb685229e560df458bcb1e49346a2b",
    "2d-refine2": "46ee90a23cfa1b2c48f21d09ca5a03d95277312a415642b5fca478005a122dd3",
    "3d": "7f5cd7fe9b693060490cba89fbcd1d88e8dfd8b147224f04ed5fbf5f5b220df0",
    "3d-aniso": "a8f2a56342838d85cacc183f4687a49cd0886e2fa168578576ccd6f8079435ac",
    "3d-refine1": "653eed8fc77fa1d6f45ba0741bc28806bff7b0f4bf4d3df124dbc1c354d2632e",
    "3d-thin-exclude0": "16c0065021a440c8602f1befe8d9010afb6a3b7df6b5c8dcea3795b0e2479b13",
}

FILE_HASHES = {
    "2d-refine2.vtk": {'m.vtk': '7774c0656a9aa22ebaefe009d8935d36e179fee97ca368ac5f5d7d0d57d0d3d9'},
    "2d.msh": {'m.msh': '70641dbcfdf49a63a88e67156c50a9fa7089dbce5094f867b07a3b1c2a5f4a5e'},
    "2d.vtu": {'m.vtu': 'b0918e006d22d1898da97ba6148daa473082aedf73c176d98b31c7a97ea19006', 'm_facets.vtu': '9a7b038aa650aa5b06bb5be8af78eb6336831d0a317ed8865836fac977224ea0'},
    "3d-aniso.node": {'m.node': 'b52a95ae574b423824779555d96f8c9047bd964a78dbe265044af24f7617eaef', 'm.ele': '87a9b609299a127494f25477d9d941bab804ffc3558a8c2944949cff1f4e8a61', 'm.face': '04687a0e7e8348736b21abcf41c18d678cbf1fd43d711c43f645d64b35f28955'},
    "3d-ascii.msh": {'m.msh': 'af98fbaa087f941f17f9e87725dc590534841464e5fd3415fc6834135e6e9120'},
    "3d-order2.inp": {'m.inp': 'f10647631336ff082e5f15e7493cd2e776ee24372c8283656eb55ce94a4bfdee'},
    "3d.inp": {'m.inp': 'beb0408f85d73a415226bb973a9c7dd41713ed429f0eb3444512dddb00273ae0'},
    "3d.msh": {'m.msh': 'eb92697cfcd3d8eb738ce77db503b49875aa59619ef95c49e1f3d915faab1d20'},
    "3d.vtu": {'m.vtu': 'f8517edf54c279a5c36fd84f6b8437caf532e6ff8bf203951620f5fd780adaf1', 'm_facets.vtu': 'edcc50dd71dd230fa583404688356bff4608204743adab0aa5c9780e0d42438f'},
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_mesh_arrays_unchanged(name):
    assert mesh_digest(name) == MESH_HASHES[name]


@pytest.mark.parametrize("name", sorted(FILE_CASES))
def test_written_files_unchanged(name, tmp_path):
    assert file_digests(name, tmp_path) == FILE_HASHES[name]


if __name__ == "__main__":
    import tempfile

    print("MESH_HASHES = {")
    for n in sorted(CASES):
        print(f'    "{n}": "{mesh_digest(n)}",')
    print("}\n\nFILE_HASHES = {")
    with tempfile.TemporaryDirectory() as tmp:
        for n in sorted(FILE_CASES):
            print(f'    "{n}": {file_digests(n, Path(tmp))!r},')
    print("}")
