"""What every file format shares: suffixes, meshio's cell-type names, the exported frame,
orientation and the material names.

Conventions written once for the writers (``_export`` and one module per awkward format)
and the pyvista bridge (``_pyvista``): exported coordinates are :func:`export_points` (x,
y(, z) = column, row(, plane), the reverse of the numpy axis order a ``Mesh`` keeps,
unless the mesh carries a ``world`` placement such as a NIfTI affine); cells are
positively oriented in those coordinates (:func:`orient_positive`); a material without a
name is called ``material_<id>``.

Format writers
--------------
A writer of one format (``write_gmsh``, ``write_abaqus``, ``write_node_ele``, ...) takes
an ``_prepare.ExportMesh`` (points and cells in the files' frame, order 1 or 2, the facet
groups chosen) and the temporary path(s) ``io.atomic_write`` gave for the target(s).
"""

from __future__ import annotations

import numpy as np

from ..model._quality import signed_volumes

__all__ = ["CELL_TYPE", "CELL_TYPE_2", "FACE_CORNERS", "MESH_SUFFIXES", "material_names",
           "export_points", "export_turns", "export_vectors", "orient_positive"]

#: meshio's name of the simplex of each dimension, linear and of second order.
CELL_TYPE = {2: "triangle", 3: "tetra"}
CELL_TYPE_2 = {2: "triangle6", 3: "tetra10"}

#: Suffix -> short description, in the order shown to users.
MESH_SUFFIXES = {
    ".vtu": "VTK XML unstructured grid (+ <stem>_facets.vtu)",
    ".vtk": "legacy VTK",
    ".msh": "Gmsh 4.1 with physical groups",
    ".xdmf": "XDMF with its HDF5 .h5 file (+ <stem>_xdmf_facets.vtu)",
    ".inp": "Abaqus with element sets and facet surfaces",
    ".node": "Triangle (2-D) / TetGen (3-D) .node + .ele (+ .poly / .face)",
    ".ele": "Triangle (2-D) / TetGen (3-D) .node + .ele (+ .poly / .face)",
}

#: Corners of the facet opposite corner k of a positively oriented simplex, ordered so
#: that the facet's normal (right-hand rule) points out of the simplex.
FACE_CORNERS = {
    2: np.array([[1, 2], [2, 0], [0, 1]]),
    3: np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]),
}


def export_points(mesh) -> np.ndarray:
    """(N, d) float64 coordinates of `mesh`'s points as every file gets them: x, y(, z).

    The one place the exported frame is decided (every writer calls it): the mesh's
    axes reversed (column, row(, plane)), or ``mesh.world`` applied to the points when
    the mesh carries one (a NIfTI image's world frame, see ``_world``).

    Examples
    --------
    >>> from napari_swa_imesh.mesh import Mesh
    >>> m = Mesh([[0, 0], [0, 2], [1, 0]], [[0, 2, 1]], [1])
    >>> export_points(m).tolist()
    [[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]]
    >>> m.world = np.array([[1., 0, 5], [0, -1, 0], [0, 0, 1]])
    >>> export_points(m).tolist()
    [[5.0, 0.0], [5.0, -2.0], [6.0, 0.0]]
    """
    points = np.asarray(mesh.points, dtype=np.float64)
    world = mesh.world
    if world is None:
        return np.ascontiguousarray(points[:, ::-1])
    d = points.shape[1]
    # einsum: a (N, 3) x (3, 3) product without BLAS's threads (2-3x faster here)
    out = np.einsum("nk,jk->nj", points, world[:d, :d])
    out += world[:d, d]
    return out


def export_turns(mesh) -> bool:
    """Whether the map of :func:`export_points` reverses orientation (its linear part has
    a negative determinant): the axes reversed, or ``mesh.world``.

    Examples
    --------
    >>> from napari_swa_imesh.mesh import Mesh
    >>> m = Mesh([[0, 0], [0, 2], [1, 0]], [[0, 2, 1]], [1])
    >>> export_turns(m)
    True
    """
    d = mesh.ndim
    linear = np.eye(d)[::-1] if mesh.world is None else np.asarray(mesh.world)[:d, :d]
    return bool(np.linalg.det(linear) < 0)


def export_vectors(mesh, vectors) -> np.ndarray:
    """(K, d) vectors given in `mesh`'s axis order (plane, row, col), in the frame of
    :func:`export_points` (a flux written beside the points must turn with them)."""
    vectors = np.asarray(vectors, dtype=np.float64)
    world = mesh.world
    if world is None:
        return np.ascontiguousarray(vectors[:, ::-1])
    d = vectors.shape[1]
    return np.einsum("nk,jk->nj", vectors, world[:d, :d])


def orient_positive(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Copy of `cells` with the first two corners swapped where the volume is negative.

    Reversing the axes for export mirrors 3-D elements (a world placement may or may not),
    so orientation is decided in the exported frame, by the sign of each volume. The
    volumes are computed in chunks (:func:`signed_volumes`): the corners of ten million
    tetrahedra at once would take a gigabyte.
    """
    cells = np.array(cells, dtype=np.intp, copy=True)
    flip = signed_volumes(points, cells) < 0
    cells[flip, 0], cells[flip, 1] = cells[flip, 1], cells[flip, 0].copy()
    return cells


def material_names(names: dict[int, str], materials: np.ndarray) -> dict[int, str]:
    """Name of each material present: from `names` (a mesh's) or ``material_<id>``.

    Raises
    ------
    ValueError
        For an empty name, one with quotes or line breaks, or two materials with one name
        (the formats that name groups could not tell them apart).

    Examples
    --------
    >>> material_names({1: "bone"}, np.array([1, 2]))
    {1: 'bone', 2: 'material_2'}
    """
    out = {int(m): str(names.get(int(m), f"material_{int(m)}")) for m in materials}
    seen: dict[str, int] = {}
    for m, name in out.items():
        if not name.strip() or '"' in name or "\n" in name:
            raise ValueError(
                f"material {m} has name {name!r}; names must be non-empty text without "
                "quotes or line breaks."
            )
        if name in seen:
            raise ValueError(
                f"materials {seen[name]} and {m} share the name {name!r}; give each "
                "material its own name."
            )
        seen[name] = m
    return out
