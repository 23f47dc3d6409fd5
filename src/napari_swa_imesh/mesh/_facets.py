"""Named facet groups of a mesh: the faces boundary conditions are put on.

Facets are the (d-1)-faces of the simplices: edges in 2-D, triangles in 3-D. Each
boundary facet and each facet between two materials belongs to exactly one group:

* ``xmin, xmax, ymin, ymax[, zmin, zmax]``: boundary facets on a side of the image box
  (x = column, y = row, z = plane, the axes of the mesh files);
* ``interface_<A>_<B>``: facets between meshed materials A and B, A the lower label;
* ``exterior_<A>``: boundary facets of material A away from the box (where A meets a
  material left out of the mesh).

Material names are those of the material groups (``material_<id>`` without a name).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._common import material_names
from ._types import Mesh

__all__ = ["FacetGroup", "facet_groups", "FACE_CORNERS"]

#: Corners of the facet opposite corner k of a positively oriented simplex, ordered so
#: that the facet's normal (right-hand rule) points out of the simplex.
FACE_CORNERS = {
    2: np.array([[1, 2], [2, 0], [0, 1]]),
    3: np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]),
}


@dataclass(frozen=True)
class FacetGroup:
    """The facets of one group.

    Attributes
    ----------
    facets : (F, d) ndarray of intp
        Vertex ids, oriented outward from `owner` (for interfaces: out of material A).
    owner : (F,) ndarray of intp
        The element each facet bounds (of material A on an interface).
    opposite : (F,) ndarray of intp
        The owner's corner opposite the facet (``0 .. d``), which fixes the element-face
        number formats such as Abaqus use.
    """

    facets: np.ndarray
    owner: np.ndarray
    opposite: np.ndarray

    def __len__(self) -> int:
        return len(self.owner)


def facet_groups(mesh: Mesh) -> dict[str, FacetGroup]:
    """Every boundary facet and every material interface of `mesh`, in named groups.

    Parameters
    ----------
    mesh : Mesh
        Positively oriented triangles or tetrahedra (the mesher's and ``read_mesh``'s
        convention).

    Returns
    -------
    dict of str to FacetGroup
        Groups in the order box sides, interfaces, exteriors; empty groups left out.

    Examples
    --------
    >>> import numpy as np
    >>> from napari_swa_imesh.mesh import mesh_labels
    >>> groups = facet_groups(mesh_labels(np.array([[1, 2]])))
    >>> {name: len(g) for name, g in groups.items()}
    {'xmin': 1, 'xmax': 1, 'ymin': 2, 'ymax': 2, 'interface_material_1_material_2': 1}
    """
    d = mesh.ndim
    corners = FACE_CORNERS[d]
    cells = np.asarray(mesh.cells, dtype=np.intp)
    m = len(cells)
    faces = cells[:, corners].reshape(-1, d)                   # (M(d+1), d) outward
    owner = np.repeat(np.arange(m), d + 1)                     # (M(d+1),)
    opposite = np.tile(np.arange(d + 1), m)
    key = np.sort(faces, axis=1)
    order = np.lexsort(key.T[::-1])
    key = key[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = (key[1:] != key[:-1]).any(axis=1)
    first = np.flatnonzero(new)                                # (G,) one per distinct facet
    count = np.diff(np.append(first, len(key)))                # 1 boundary, 2 shared
    a = order[first]                                           # index into faces
    b = order[np.minimum(first + 1, len(key) - 1)]
    material = np.asarray(mesh.material)

    groups: dict[str, FacetGroup] = {}

    def add(name: str, rows: np.ndarray) -> None:
        if rows.size:
            groups[name] = FacetGroup(faces[rows], owner[rows], opposite[rows])

    boundary = a[count == 1]
    lo, hi = mesh.image_box()
    coords = mesh.points[faces[boundary]]                      # (B, d, d)
    on_side = np.zeros(len(boundary), dtype=bool)
    tol = 1e-9 * (hi - lo)
    for axis_name, axis in zip("xyz"[:d], range(d - 1, -1, -1)):
        values = coords[:, :, axis]
        for end, plane in (("min", lo[axis]), ("max", hi[axis])):
            hit = np.all(np.abs(values - plane) <= tol[axis], axis=1) & ~on_side
            add(f"{axis_name}{end}", boundary[hit])
            on_side |= hit

    names = material_names(mesh.material_names, np.unique(material))
    shared = count == 2
    fa, fb = a[shared], b[shared]
    ma, mb = material[owner[fa]], material[owner[fb]]
    differ = ma != mb
    fa, fb, ma, mb = fa[differ], fb[differ], ma[differ], mb[differ]
    side_a = np.where(ma < mb, fa, fb)                         # the facet as seen from A
    low, high = np.minimum(ma, mb), np.maximum(ma, mb)
    pairs = np.unique(np.stack([low, high], axis=1), axis=0) if len(low) else []
    for x, y in pairs:
        add(f"interface_{names[int(x)]}_{names[int(y)]}", side_a[(low == x) & (high == y)])

    exterior = boundary[~on_side]
    for mat in np.unique(material[owner[exterior]]):
        add(f"exterior_{names[int(mat)]}", exterior[material[owner[exterior]] == mat])
    return groups
