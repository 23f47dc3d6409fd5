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
  writer, with extra fields); the formats, one :class:`MeshFormat` record each, by
  :func:`mesh_format` (of a path) and :func:`mesh_formats` (all, as users see them);
* placement: ``mesh_labels(..., affine=...)`` puts the files in an image's world frame
  (NIfTI); :func:`world_from_affine` gives the spacing and ``Mesh.world`` it uses,
  :func:`image_placement` both for a label image file;
* facet groups for boundary conditions: :func:`facet_groups` (box sides, material
  interfaces, exteriors);
* memory: :func:`estimate_mesh_memory`, :func:`count_boundary_voxels`;
* display: :func:`shown_faces` (boundary and material-interface faces),
  :func:`mesh_surface` (per-triangle vertices and values for a surface view),
  :func:`clip_cells` and :class:`MeshClipper` (the whole elements on one side of a plane,
  and the surface of that set); :meth:`Mesh.to_pyvista` for VTK's own filters;
* for the steps above mesh: :data:`MESH_SUFFIXES`, the lattice (:class:`Lattice`,
  :data:`ASPECT_LIMIT`, :data:`MAX_REFINE`, :func:`check_refine`, :func:`check_max_aspect`),
  :func:`voxel_sizes`, :func:`paired_facets`, :func:`export_vectors`, adaptive refinement
  (:func:`refine_marked`, and ``refine_marked_tree`` which also takes and returns the
  region tree), and the mesher's door and worker apart (``mesh_arguments`` checks
  what :func:`mesh_labels` takes, ``mesh_checked_labels`` meshes them and returns the
  mesh and its tree).
"""

from .._region_tree import RegionTree, build_tree
from .checks._checks import MeshChecks, check_mesh, rasterize_materials
from .checks._clip import MeshClipper, clip_cells
from .checks._facets import FacetGroup, facet_groups, paired_facets
from .checks._surface import mesh_surface, shown_faces
from .formats._common import export_vectors
from .formats._export import read_mesh, to_meshio, write_mesh, write_mesh_vtu
from .formats._registry import MESH_SUFFIXES, MeshFormat, mesh_format, mesh_formats
from .mesher._adapt import _refine_marked as refine_marked_tree
from .mesher._adapt import refine_marked
from .mesher._balance import balance_tree
from .mesher._imesh import MeshPlan, mesh_labels, mesh_tree, plan_mesh
from .mesher._imesh import _mesh_arguments as mesh_arguments
from .mesher._imesh import _mesh_labels as mesh_checked_labels
from .mesher._lattice import ASPECT_LIMIT, MAX_REFINE, Lattice, check_max_aspect, check_refine
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
from .model._world import image_placement, voxel_sizes, world_from_affine

__all__ = [
    "FacetGroup", "facet_groups", "write_mesh_vtu", "Mesh", "balance_tree", "mesh_labels",
    "mesh_tree", "check_mesh", "MeshChecks",
    "rasterize_materials", "QUALITY_METRICS", "dihedral_angles", "max_angle", "min_angle",
    "radius_edge_ratio", "signed_volumes", "quality_bounds", "quality_table",
    "format_quality_table", "read_mesh", "to_meshio", "write_mesh", "estimate_mesh_memory",
    "count_boundary_voxels", "mesh_surface", "shown_faces", "world_from_affine",
    "MeshClipper", "clip_cells", "RegionTree", "build_tree",
    "MeshFormat", "mesh_format", "mesh_formats", "MeshPlan", "plan_mesh",
    # for the packages above mesh (simulate, pipeline, the widgets), issue 24
    "MESH_SUFFIXES", "ASPECT_LIMIT", "MAX_REFINE", "Lattice", "check_refine",
    "check_max_aspect", "voxel_sizes", "paired_facets", "export_vectors", "refine_marked",
    "refine_marked_tree", "mesh_arguments", "mesh_checked_labels", "image_placement",
]
