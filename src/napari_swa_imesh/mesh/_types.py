"""The mesh container shared by the mesher, the quality metrics, the checks and the writers.

Conventions
-----------
* ``points`` are physical coordinates in numpy/napari axis order (plane, row, column),
  i.e. pixel corner index times spacing. The image box is ``[0, shape[a]*spacing[a]]``.
* ``cells`` index ``points``; every cell has positive signed volume in these coordinates:
  ``det([p1-p0, p2-p0(, p3-p0)]) > 0`` with columns in axis order.
* Writers (``to_meshio``) reverse the axes to x, y(, z) = column, row(, plane), the order
  FE tools expect, and reorder each cell so its volume stays positive there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Mesh"]


@dataclass
class Mesh:
    """A simplicial mesh with one material per element.

    Attributes
    ----------
    points : (N, d) ndarray of float64
        Vertex coordinates, physical units, axis order of the image.
    cells : (M, d+1) ndarray of intp
        Triangles (d=2) or tetrahedra (d=3), positively oriented.
    material : (M,) ndarray of int64
        Label of the leaf each element lies in.
    cell_data : dict of str to (M,) ndarray
        Per-element data: at least ``quality`` (radius-to-edge ratio) and ``level`` (leaf
        level); the mesher adds angle metrics.
    spacing : tuple of float
        Voxel spacing used to place the points.
    shape : tuple of int
        Shape of the label image that was meshed.
    material_names : dict of int to str
        Optional names for material ids (used by Gmsh physical groups and Abaqus sets).
    info : dict
        Counts and timings of the run that made the mesh (for reports and ``--json``).
    """

    points: np.ndarray
    cells: np.ndarray
    material: np.ndarray
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)
    spacing: tuple[float, ...] = ()
    shape: tuple[int, ...] = ()
    material_names: dict[int, str] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    @property
    def ndim(self) -> int:
        return int(self.points.shape[1])

    @property
    def n_cells(self) -> int:
        return int(self.cells.shape[0])

    @property
    def quality(self) -> np.ndarray:
        """(M,) radius-to-edge ratio of each element."""
        return self.cell_data["quality"]
