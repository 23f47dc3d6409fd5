"""Facet groups by name: :class:`FacetGroup` and the naming of boundary and interface
facets (box sides, ``interface_<A>_<B>``, ``exterior_<A>``), shared by the two ways
``_facets.facet_groups`` finds the facets (leaf by leaf, or by sorting)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..formats._common import FACE_CORNERS, material_names
from ..model._types import Mesh
from ._leaf_facets import present_materials

__all__ = ["FacetGroup", "named_groups"]


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

    facets: np.ndarray | None
    owner: np.ndarray
    opposite: np.ndarray

    def __len__(self) -> int:
        return len(self.owner)


def named_groups(mesh: Mesh, cells, material, b_owner, b_opposite, i_owner, i_opposite,
                 i_other, facets: bool = True) -> dict[str, FacetGroup]:
    """The groups of :func:`facet_groups` from boundary facets (owner, opposite corner)
    and interface facets (owner of material A, its opposite corner, material B), each
    in lexicographic order. Without `facets`, the groups' ``facets`` are None (for a
    caller that builds them from owner and corner in its own frame)."""
    d = mesh.ndim
    groups: dict[str, FacetGroup] = {}

    def add(name: str, owner: np.ndarray, corner: np.ndarray) -> None:
        if owner.size:
            groups[name] = FacetGroup(
                cells[owner[:, None], FACE_CORNERS[d][corner]] if facets else None,
                owner, corner)

    lo, hi = mesh.image_box()
    coords = mesh.points[cells[b_owner[:, None], FACE_CORNERS[d][b_opposite]]]   # (B, d, d)
    on_side = np.zeros(len(b_owner), dtype=bool)
    tol = 1e-9 * (hi - lo)
    for axis_name, axis in zip("xyz"[:d], range(d - 1, -1, -1)):
        values = coords[:, :, axis]
        for end, plane in (("min", lo[axis]), ("max", hi[axis])):
            hit = np.all(np.abs(values - plane) <= tol[axis], axis=1) & ~on_side
            add(f"{axis_name}{end}", b_owner[hit], b_opposite[hit])
            on_side |= hit
    del coords

    present = present_materials(material)
    names = material_names(mesh.material_names, present)
    # (A, B) pairs by their ranks among the materials: no sort of the facets
    rank = np.searchsorted(present, np.stack([material[i_owner], i_other]))
    pair = rank[0] * len(present) + rank[1]
    for code in np.flatnonzero(np.bincount(pair, minlength=len(present) ** 2)):
        x, y = present[code // len(present)], present[code % len(present)]
        mine = pair == code
        add(f"interface_{names[int(x)]}_{names[int(y)]}", i_owner[mine], i_opposite[mine])

    b_owner, b_opposite = b_owner[~on_side], b_opposite[~on_side]
    outside = material[b_owner]
    for mat in present_materials(outside):
        mine = outside == mat
        add(f"exterior_{names[int(mat)]}", b_owner[mine], b_opposite[mine])
    return groups
