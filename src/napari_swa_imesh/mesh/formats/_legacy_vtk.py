"""Legacy VTK (``.vtk``, VTK 4.2) through meshio, and the meshio mesh of a prepared mesh.

Points padded to z = 0 in 2-D (VTK needs 3-D points); every per-cell array as 64-bit
integers or floats; no facet groups (the format has no place for them).
"""

from __future__ import annotations

import numpy as np

from ._common import CELL_TYPE, CELL_TYPE_2
from ._prepare import ExportMesh

__all__ = ["write_legacy_vtk"]


def write_legacy_vtk(ex: ExportMesh, path) -> None:
    """Write `ex` to `path` as binary legacy VTK 4.2 (ValueError for meshio's failures)."""
    import meshio

    try:
        meshio.write(str(path), _padded(_meshio_of(ex)), file_format="vtk42", binary=True)
    except (meshio.WriteError, KeyError) as exc:  # meshio's own failures, in one line
        raise ValueError(f"meshio could not write {path.name}: {exc}") from exc


def _meshio_of(ex: ExportMesh):
    import meshio

    cell_data = {"material": [ex.material]}
    for key, values in ex.mesh.cell_data.items():
        values = np.asarray(values)
        # every writer takes int64/float64; some reject int8 or bool (XDMF as XML)
        kind = values.dtype.kind
        cell_data[key] = [values.astype(np.int64 if kind in "biu" else np.float64)]
    cell_type = (CELL_TYPE if ex.order == 1 else CELL_TYPE_2)[ex.ndim]
    return meshio.Mesh(ex.points, [(cell_type, ex.all_cells())], cell_data=cell_data)


def _padded(m):
    """The same meshio mesh with 2-D points given z = 0 (VTK formats need 3-D points)."""
    import meshio

    if m.points.shape[1] == 3:
        return m
    points = np.column_stack([m.points, np.zeros(len(m.points))])
    return meshio.Mesh(points, m.cells, cell_data=m.cell_data)
