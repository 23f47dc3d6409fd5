"""IMESH: conforming, quality-guaranteed simplex meshes of label images.

* tree and balance: :func:`build_tree` (a :class:`RegionTree`; also
  ``napari_swa_imesh.build_tree``), :func:`balance_tree`;
* meshing: :func:`mesh_labels` (``method="template"`` by default, or the reference's
  ``"delaunay"``), returning a :class:`Mesh`;
* checks: :func:`check_mesh` (a :class:`MeshChecks` report), :func:`rasterize_materials`;
* quality: :func:`radius_edge_ratio`, :func:`min_angle`, :func:`dihedral_angles`,
  :func:`signed_volumes`, :data:`QUALITY_METRICS`, and the method's proven bounds,
  :func:`quality_table` and the ranges they prove per metric, :func:`quality_bounds`;
* export: :func:`write_mesh` (every format, order 1 or 2, with the facet groups asked
  for), :func:`read_mesh`, :func:`to_meshio`, and :func:`write_mesh_vtu` (the ``.vtu``
  writer, with extra fields);
* placement: ``mesh_labels(..., affine=...)`` puts the files in an image's world frame
  (NIfTI); :func:`world_from_affine` gives the spacing and ``Mesh.world`` it uses;
* facet groups for boundary conditions: :func:`facet_groups` (box sides, material
  interfaces, exteriors);
* memory: :func:`estimate_mesh_memory`, :func:`count_boundary_voxels`;
* display: :func:`shown_faces` (boundary and material-interface faces),
  :func:`mesh_surface` (per-triangle vertices and values for a surface view),
  :func:`clip_cells` and :class:`MeshClipper` (the whole elements on one side of a plane,
  and the surface of that set); :meth:`Mesh.to_pyvista` for VTK's own filters.
"""

from .checks._checks import MeshChecks, check_mesh, rasterize_materials
from .checks._clip import MeshClipper, clip_cells
from .checks._facets import FacetGroup, facet_groups
from .checks._surface import mesh_surface, shown_faces
from .formats._export import read_mesh, to_meshio, write_mesh, write_mesh_vtu
from .mesher._balance import balance_tree
from .mesher._imesh import mesh_labels, mesh_tree
from .mesher._tree import RegionTree, build_tree
from .model._bounds import format_quality_table, quality_bounds, quality_table
from .model._memory import count_boundary_voxels, estimate_mesh_memory
from .model._quality import (
    QUALITY_METRICS,
    dihedral_angles,
    max_angle,
    min_angle,
    radius_edge_ratio,
    signed_volumes,
)
from .model._types import Mesh
from .model._world import world_from_affine

__all__ = [
    "FacetGroup", "facet_groups", "write_mesh_vtu", "Mesh", "balance_tree", "mesh_labels", "mesh_tree", "check_mesh", "MeshChecks",
    "rasterize_materials", "QUALITY_METRICS", "dihedral_angles", "max_angle", "min_angle",
    "radius_edge_ratio", "signed_volumes", "quality_bounds", "quality_table",
    "format_quality_table", "read_mesh", "to_meshio", "write_mesh", "estimate_mesh_memory",
    "count_boundary_voxels", "mesh_surface", "shown_faces", "world_from_affine",
    "MeshClipper", "clip_cells", "RegionTree", "build_tree",
]
