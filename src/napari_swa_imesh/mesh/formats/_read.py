"""Reading a mesh file back into a ``Mesh``: every format ``write_mesh`` writes.

Files of second order give their linear mesh (corners of each element; the mid-edge
nodes are dropped); facet elements (Gmsh physical groups of dimension d-1) are skipped:
only the elements of the mesh's own dimension are read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model._types import Mesh
from ._common import orient_positive
from ._registry import PARTITIONED, PVTU, MeshFormat, UnknownSuffixError, mesh_format

__all__ = ["read_mesh"]


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
    if p.suffix.lower() in PARTITIONED:          # block-wise pieces (issue 27)
        from ..blocks import is_xdmf_index, read_pvtu

        if p.suffix.lower() == PVTU or is_xdmf_index(p):
            return read_pvtu(p)
    found: MeshFormat | UnknownSuffixError
    try:
        found = mesh_format(p, action="read")
    except UnknownSuffixError as exc:
        found = exc
    # a format named by either of its files (.node/.ele) reads the pair, whichever is given
    if not p.exists() and (isinstance(found, UnknownSuffixError) or len(found.suffixes) == 1):
        raise FileNotFoundError(f"no mesh file at {p}; check the path.")
    if isinstance(found, UnknownSuffixError):
        raise found
    fmt = found
    if fmt.read is None:
        raise ValueError(f"{fmt.called} files are written, not read; give another mesh file.")
    if fmt.requires is not None:
        fmt.requires("read")
    points, cells, material, cell_data, names = fmt.read(p)
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
