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

__all__ = ["FacetGroup", "facet_groups", "paired_facets", "FACE_CORNERS"]

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


def paired_facets(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every distinct facet of a simplex mesh once, with the one or two elements it bounds.

    Parameters
    ----------
    cells : (M, d+1) ndarray of int
        Positively oriented triangles or tetrahedra.

    Returns
    -------
    facets : (G, d) ndarray of intp
        Oriented out of its first owner.
    owners : (G, 2) ndarray of intp
        The elements on either side; the second is -1 on the boundary.
    opposite : (G, 2) ndarray of intp
        Each owner's corner opposite the facet (-1 where there is no second owner).
    """
    cells = np.asarray(cells, dtype=np.intp)
    d = cells.shape[1] - 1
    faces = cells[:, FACE_CORNERS[d]].reshape(-1, d)          # (M(d+1), d) outward
    key = np.sort(faces, axis=1)                               # orientation-free
    order = np.lexsort(key.T[::-1])
    key = key[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = (key[1:] != key[:-1]).any(axis=1)
    first = np.flatnonzero(new)                                # (G,) start of each facet
    shared = np.diff(np.append(first, len(key))) == 2          # 1 boundary, 2 shared
    one = order[first]                                         # rows of `faces`
    two = np.where(shared, order[np.minimum(first + 1, len(key) - 1)], -1)
    owners = np.stack([one // (d + 1), np.where(shared, two // (d + 1), -1)], axis=1)
    opposite = np.stack([one % (d + 1), np.where(shared, two % (d + 1), -1)], axis=1)
    return faces[one], owners, opposite


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
    cells = np.asarray(mesh.cells, dtype=np.intp)
    facets, owners, opposite = paired_facets(cells)
    material = np.asarray(mesh.material)

    groups: dict[str, FacetGroup] = {}

    def add(name: str, rows: np.ndarray, side: np.ndarray | int = 0) -> None:
        # side: which owner (0 or 1, per facet) the facet is seen from
        if rows.size:
            owner, corner = owners[rows, side], opposite[rows, side]
            groups[name] = FacetGroup(cells[owner[:, None], FACE_CORNERS[d][corner]],
                                      owner, corner)

    boundary = np.flatnonzero(owners[:, 1] < 0)
    lo, hi = mesh.image_box()
    coords = mesh.points[facets[boundary]]                     # (B, d, d)
    on_side = np.zeros(len(boundary), dtype=bool)
    tol = 1e-9 * (hi - lo)
    for axis_name, axis in zip("xyz"[:d], range(d - 1, -1, -1)):
        values = coords[:, :, axis]
        for end, plane in (("min", lo[axis]), ("max", hi[axis])):
            hit = np.all(np.abs(values - plane) <= tol[axis], axis=1) & ~on_side
            add(f"{axis_name}{end}", boundary[hit])
            on_side |= hit

    names = material_names(mesh.material_names, np.unique(material))
    shared = np.flatnonzero(owners[:, 1] >= 0)
    ma, mb = material[owners[shared, 0]], material[owners[shared, 1]]
    differ = ma != mb
    shared, ma, mb = shared[differ], ma[differ], mb[differ]
    low, high = np.minimum(ma, mb), np.maximum(ma, mb)
    pairs = np.unique(np.stack([low, high], axis=1), axis=0) if len(low) else []
    for x, y in pairs:
        pair = (low == x) & (high == y)
        # each facet as seen from material A, the lower label
        add(f"interface_{names[int(x)]}_{names[int(y)]}", shared[pair],
            side=(ma[pair] != x).astype(np.intp))

    exterior = boundary[~on_side]
    outside = material[owners[exterior, 0]]
    for mat in np.unique(outside):
        add(f"exterior_{names[int(mat)]}", exterior[outside == mat])
    return groups
