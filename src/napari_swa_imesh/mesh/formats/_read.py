"""Reading a mesh file back into a ``Mesh``: every format ``write_mesh`` writes.

Files of second order give their linear mesh (corners of each element; the mid-edge
nodes are dropped); facet elements (Gmsh physical groups of dimension d-1) are skipped:
only the elements of the mesh's own dimension are read.
"""

from __future__ import annotations

import io
import warnings
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from ._abaqus import abaqus_materials
from ._common import MESH_SUFFIXES, orient_positive
from ._gmsh import gmsh_materials
from ._triangle_tetgen import read_node_ele
from ..model._types import Mesh
from ._xdmf import require_h5py

__all__ = ["read_mesh"]

#: meshio cell types read, by dimension: linear and second order.
_TYPES = {3: ("tetra", "tetra10"), 2: ("triangle", "triangle6")}


def read_mesh(path) -> Mesh:
    """Read a mesh written by `write_mesh` (or a compatible file) back into a `Mesh`.

    Parameters
    ----------
    path : str or Path
        Any suffix `write_mesh` writes; for Triangle/TetGen either ``.node`` or ``.ele``.

    Returns
    -------
    Mesh
        Points back in numpy axis order (plane, row, col), 2-D when the file holds
        triangles with z = 0; cells positively oriented there; ``material`` from the
        ``material`` array, Gmsh physical groups, Abaqus element sets or the
        Triangle/TetGen region attribute (0 for every element when the file has none,
        and then ``info["has_material"]`` is False); other per-cell arrays as stored. ``spacing``
        and ``shape`` are unknown (empty). Cell order may differ from the written mesh
        (Gmsh groups cells by material). A second-order file gives its corners only.
    """
    p = Path(path)
    if not p.exists() and p.suffix.lower() not in (".node", ".ele"):
        raise FileNotFoundError(f"no mesh file at {p}; check the path.")
    suffix = p.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(
            f"cannot read a mesh from {p.name!r}: unknown suffix {suffix!r}; use one of "
            f"{', '.join(MESH_SUFFIXES)}."
        )
    names: dict[int, str] = {}
    if suffix in (".node", ".ele"):
        points, cells, attributes = read_node_ele(p)
        material = attributes.pop("material", None)
        cell_data = attributes
    else:
        points, cells, material, cell_data, names = _read_meshio(p, suffix)
    used = np.zeros(len(points), dtype=bool)
    used[cells.ravel()] = True
    if not used.all():                             # mid-edge nodes of a second-order file
        new_id = np.cumsum(used) - 1
        points, cells = points[used], new_id[cells]
    if points.shape[1] == 3 and cells.shape[1] == 3:
        if np.any(points[:, 2] != 0):
            raise ValueError(
                f"{p} holds triangles in 3-D space; only flat 2-D meshes are supported."
            )
        points = points[:, :2]
    points = np.ascontiguousarray(points[:, ::-1], dtype=np.float64)
    cells = orient_positive(points, cells)
    has_material = material is not None
    if material is None:
        material = np.zeros(len(cells), dtype=np.int64)
    return Mesh(
        points=points,
        cells=cells,
        material=np.rint(material).astype(np.int64),
        cell_data={k: np.asarray(v) for k, v in cell_data.items()},
        material_names=names,
        info={"source": str(p), "has_material": has_material},
    )


def _read_meshio(p: Path, suffix: str):
    import meshio

    fmt = {".vtu": "vtu", ".vtk": "vtk", ".xdmf": "xdmf", ".msh": "gmsh", ".inp": "abaqus"}[suffix]
    if fmt == "xdmf":
        require_h5py("read")
    said = io.StringIO()   # meshio prints its errors and warnings, then may exit
    try:
        with redirect_stdout(said), redirect_stderr(said):
            m = meshio.read(p, file_format=fmt)
    except SystemExit as exc:
        # meshio printed the ReadError of a file it could not parse; its Abaqus reader
        # also exits on element types it lacks
        if "Element type not available" not in said.getvalue():
            raise ValueError(_damaged(p, suffix, _first_line(said))) from exc
        raise ValueError(f"cannot read {p}: meshio does not know one of its element types "
                         f"(it has no CPS6/DC2D6, the 2-D second-order types); read the "
                         f"mesh from a .vtu or .msh file instead.") from exc
    except Exception as exc:  # a cut or corrupt file fails anywhere in meshio's parsers
        raise ValueError(_damaged(p, suffix, f"{type(exc).__name__}: {exc}")) from exc
    if "not closed" in said.getvalue():      # a section cut off at the end of the file
        raise ValueError(_damaged(p, suffix, _first_line(said)))
    if said.getvalue().strip():
        warnings.warn(f"meshio, reading {p.name}: {_first_line(said)}", stacklevel=3)
    _check_complete(p, suffix, m)
    types = {b.type for b in m.cells}
    dim = 3 if types & set(_TYPES[3]) else 2      # facet triangles of a 3-D file are skipped
    keep = [i for i, block in enumerate(m.cells) if block.type in _TYPES[dim]]
    if not keep or len({m.cells[i].type for i in keep}) != 1:
        raise ValueError(
            f"{p} must hold triangles or tetrahedra (one kind, linear or of second "
            f"order); found {sorted(types)}."
        )
    cells = np.concatenate([m.cells[i].data[:, :dim + 1] for i in keep]).astype(np.intp)
    cell_data = {
        key: np.concatenate([np.asarray(blocks[i]) for i in keep])
        for key, blocks in m.cell_data.items()
        if not key.startswith("gmsh:")
    }
    names: dict[int, str] = {}
    material = cell_data.pop("material", None)
    if fmt == "gmsh":
        names, physical_material = gmsh_materials(m, keep)
        if material is None:
            material = physical_material
    elif fmt == "abaqus":
        names, material = abaqus_materials(p, m, keep, len(cells))
    return np.asarray(m.points, dtype=np.float64), cells, material, cell_data, names


def _first_line(text: io.StringIO) -> str:
    lines = [ln.strip() for ln in text.getvalue().splitlines() if ln.strip()]
    return lines[0] if lines else "no message"


def _damaged(p: Path, suffix: str, what: str) -> str:
    return (f"cannot read {p} as a {suffix} mesh: the file is truncated or damaged ({what}); "
            "write it again (or copy it again in full).")


def _check_complete(p: Path, suffix: str, m) -> None:
    """Refuse a file meshio parsed only in part: cells naming points it lacks, per-cell
    arrays shorter than their cells, points that are not numbers."""
    n = len(m.points)
    points = np.asarray(m.points)
    if points.ndim != 2 or (points.size and not np.isfinite(points).all()):
        raise ValueError(_damaged(p, suffix, "its points are not all finite numbers"))
    for i, block in enumerate(m.cells):
        data = np.asarray(block.data)
        if data.size and (data.min() < 0 or data.max() >= n):
            raise ValueError(_damaged(p, suffix, f"its {block.type} cells name points "
                                      f"beyond the {n} it holds"))
        for key, blocks in m.cell_data.items():
            if i < len(blocks) and len(blocks[i]) != len(data):
                raise ValueError(_damaged(p, suffix, f"{key!r} holds {len(blocks[i])} values "
                                          f"for {len(data)} {block.type} cells"))
        if any(i >= len(blocks) for blocks in m.cell_data.values()):
            raise ValueError(_damaged(p, suffix, f"per-cell data is missing for its "
                                      f"{block.type} cells"))
