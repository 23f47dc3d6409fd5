"""The bridge to pyvista (VTK): a ``Mesh`` as a ``pyvista.UnstructuredGrid``.

pyvista is imported when the bridge is used, never with the package (it is an optional
dependency, and VTK takes a second to load). The grid is in the exported frame (x, y(, z)
from :func:`._common.export_points`, cells positive there, as every file writer gives
them), so it matches what ParaView shows of the mesh's ``.vtu``.
"""

from __future__ import annotations

import numpy as np

from ._common import export_points, orient_positive

__all__ = ["to_pyvista", "VTK_CELL_TYPE"]

#: VTK cell type of the simplex of each dimension (VTK_TRIANGLE, VTK_TETRA).
VTK_CELL_TYPE = {2: 5, 3: 10}


def to_pyvista(mesh):
    """`mesh` as a ``pyvista.UnstructuredGrid`` (see :meth:`Mesh.to_pyvista`)."""
    try:
        import pyvista as pv
    except ImportError as exc:  # optional: only this bridge needs it
        raise ImportError("Mesh.to_pyvista needs pyvista; install it with "
                          "`pip install pyvista`.") from exc
    points = export_points(mesh)
    cells = orient_positive(points, mesh.cells)
    if mesh.ndim == 2:   # VTK points are 3-D: the plane z = 0
        points = np.column_stack([points, np.zeros(len(points))])
    grid = pv.UnstructuredGrid({VTK_CELL_TYPE[mesh.ndim]: cells}, points)
    grid.cell_data["material"] = mesh.material
    for name, values in mesh.cell_data.items():
        grid.cell_data[name] = values
    return grid
