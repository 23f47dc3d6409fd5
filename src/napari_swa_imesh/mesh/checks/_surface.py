"""What a Surface view (napari's, or any) shows of a mesh: triangles with their own vertices.

Pure numpy: the widget package adapts the result to a napari layer.

A Surface layer carries only triangles and colours by vertex. To colour each element by
its own value (quality or material) without neighbours blending, every triangle gets three
vertices of its own: vertices ``(3F, d)``, faces ``arange(3F).reshape(F, 3)``, and one
value per vertex repeated from its triangle. In 3-D the triangles shown are the faces of
the tetrahedra that matter to a reader: the boundary of the meshed region and the
interfaces between materials (interior faces between two elements of one material are
left out).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._facets import paired_facets

__all__ = ["shown_faces", "per_triangle_surface", "mesh_surface"]

def shown_faces(cells: np.ndarray, material: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles to draw for a triangle or tetrahedron mesh, and the elements they bound.

    Parameters
    ----------
    cells : (M, 3) or (M, 4) ndarray of int
    material : (M,) ndarray of int

    Returns
    -------
    faces : (F, 3) ndarray of intp
        Triangles (vertex indices). For triangles: the cells themselves. For tetrahedra:
        boundary faces and material-interface faces, each once.
    owners : (F, 2) ndarray of intp
        The element(s) each face belongs to; the second is -1 on the boundary (and for
        2-D, where each face is its own element).

    Examples
    --------
    >>> tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    >>> faces, owners = shown_faces(tets, np.array([1, 1]))
    >>> len(faces)          # 8 faces, the shared one is interior to one material
    6
    >>> len(shown_faces(tets, np.array([1, 2]))[0])     # now it is an interface
    7
    """
    cells = np.asarray(cells, dtype=np.intp)
    m = len(cells)
    if cells.shape[1] == 3:
        return cells, np.stack([np.arange(m), np.full(m, -1)], axis=1)
    faces, owners, _ = paired_facets(cells)
    shared = owners[:, 1] >= 0
    interface = shared & (material[owners[:, 0]] != material[np.maximum(owners[:, 1], 0)])
    keep = ~shared | interface
    return faces[keep], owners[keep]


def per_triangle_surface(points: np.ndarray, faces: np.ndarray, face_values: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface data in which every triangle owns its three vertices.

    Returns
    -------
    vertices : (3F, d) ndarray of float64
    triangles : (F, 3) ndarray of intp
        ``arange(3F).reshape(F, 3)``.
    vertex_values : (3F,) ndarray of float64
        Each triangle's value on its three vertices.

    Examples
    --------
    >>> v, t, val = per_triangle_surface(np.eye(3)[:, :2], np.array([[0, 1, 2]]), np.array([7.]))
    >>> v.shape, t.tolist(), val.tolist()
    ((3, 2), [[0, 1, 2]], [7.0, 7.0, 7.0])
    """
    f = len(faces)
    points = np.asarray(points, dtype=np.float64)
    vertices = points[faces].reshape(3 * f, points.shape[1])   # shape known when F = 0
    triangles = np.arange(3 * f, dtype=np.intp).reshape(f, 3)
    return vertices, triangles, np.repeat(np.asarray(face_values, dtype=np.float64), 3)


def mesh_surface(mesh) -> dict[str, Any]:
    """Everything a Surface layer needs to show `mesh`, in both colourings.

    Parameters
    ----------
    mesh : Mesh
        Triangles or tetrahedra with ``quality`` in ``cell_data``.

    Returns
    -------
    dict
        ``vertices (3F, d)``, ``triangles (F, 3)``, ``quality (3F,)`` (the worse
        radius-to-edge ratio of the face's elements), ``material (3F,)`` (of the face's
        first element), ``n_faces``, and ``faces (F, 3)`` and ``owners (F, 2)`` from
        :func:`shown_faces` (a clipped view starts from them).
    """
    faces, owners = shown_faces(mesh.cells, mesh.material)
    q = mesh.quality
    worst = np.where(owners[:, 1] >= 0, np.maximum(q[owners[:, 0]], q[np.maximum(owners[:, 1], 0)]),
                     q[owners[:, 0]])
    vertices, triangles, quality = per_triangle_surface(mesh.points, faces, worst)
    material = np.repeat(mesh.material[owners[:, 0]], 3)
    return {"vertices": vertices, "triangles": triangles, "quality": quality,
            "material": material, "n_faces": len(faces), "faces": faces, "owners": owners}
