"""What every writer gets: the mesh in the files' frame, of order 1 or 2, with the facet
groups asked for.

* Points: ``_common.export_points`` (the one place the exported frame is decided), then,
  for second order, the mid-edge nodes (``_order2``).
* Cells: positive in that frame (corners 0 and 1 swapped where the volume is negative),
  given block by block so that streaming writers never hold a second copy of the mesh.
* Facet groups (``_facets.facet_groups``): the selection asked for (``"all"``, ``"none"``
  or names and ``*`` patterns), each facet oriented out of its owner *in the files'
  frame*, with the owner's corner opposite it counted in the cell as written (which fixes
  element-face numbers such as Abaqus ``S1``..``S4``). Group ids run 1..K in the order of
  :func:`facet_groups` among the groups written.
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase

import numpy as np

from ..._validation import OptionError
from ..checks._facets import FACE_CORNERS, groups_and_signs
from ..checks._leaf_facets import present_materials
from ..model._quality import _corner_det
from ..model._types import Mesh
from ._common import export_points, export_turns, material_names
from ._order2 import MidEdges, with_mid_nodes
from ._vtu import CellBlocks

__all__ = ["ExportMesh", "FileFacets", "check_facet_selection", "select_facet_groups",
           "box_sides", "ORDERS"]

ORDERS = (1, 2)
_WILDCARDS = "*?["
_SLICE = 1 << 17                  # elements per pass of the orientation test


def box_sides(ndim: int) -> list[str]:
    """Names of the box-side groups of a `ndim`-D mesh, in :func:`facet_groups` order."""
    return [f"{axis}{end}" for axis in "xyz"[:ndim] for end in ("min", "max")]


def check_facet_selection(selection, ndim: int | None = None):
    """The facet-group selection in one form: ``"all"``, ``"none"`` or a tuple of names.

    Names are checked against what can be known before meshing: box sides of the
    dimension (all three axes when `ndim` is None), ``interface_...``, ``exterior_...``,
    or a pattern with ``*``, ``?`` or ``[``.

    Raises
    ------
    ValueError
        Another string, an empty list, or a name no mesh of that dimension can have.
    TypeError
        Something that is neither a string nor a list of strings.

    Examples
    --------
    >>> check_facet_selection(["xmin", "interface_*", "xmin"], 2)
    ('xmin', 'interface_*')
    """
    if isinstance(selection, str):
        if selection in ("all", "none"):
            return selection
        raise OptionError("facet_groups", "{option} must be 'all', 'none' or a list of "
                          f"group names; got {OptionError.quote(selection)}.")
    try:
        names = list(selection)
    except TypeError:
        raise TypeError(f"facet_groups must be 'all', 'none' or a list of group names; "
                        f"got {type(selection).__name__}.") from None
    if not all(isinstance(n, str) and n.strip() for n in names):
        raise OptionError("facet_groups", "{option} must list non-empty group names "
                          f"(strings); got {OptionError.quote(names)}.")
    if not names:
        raise OptionError("facet_groups", "{option} lists no group; pass 'none' to write no "
                          "facet group.")
    sides = box_sides(ndim or 3)
    for name in names:
        if not (name in sides or name.startswith(("interface_", "exterior_"))
                or any(c in name for c in _WILDCARDS)):
            raise ValueError(
                f"unknown facet group {name!r}; the groups are {', '.join(sides)}, "
                "interface_<A>_<B> and exterior_<A> (A, B material names), or patterns "
                "such as interface_*.")
    return tuple(dict.fromkeys(n.strip() for n in names))


def select_facet_groups(groups: dict, selection) -> dict:
    """The groups of `groups` (name -> group, in order) that `selection` asks for.

    Raises
    ------
    ValueError
        A name or pattern that matches no group of this mesh (the message lists them).
    """
    if selection == "all":
        return groups
    if selection == "none":
        return {}
    chosen: set[str] = set()
    for name in selection:
        if any(c in name for c in _WILDCARDS):
            hits = [g for g in groups if fnmatchcase(g, name)]
        else:
            hits = [name] if name in groups else []
        if not hits:
            raise ValueError(f"facet group {name!r} is not in this mesh; its groups are "
                             f"{', '.join(groups) or '(none)'}.")
        chosen.update(hits)
    return {name: g for name, g in groups.items() if name in chosen}


@dataclass(frozen=True)
class FileFacets:
    """One facet group as the files get it.

    Attributes
    ----------
    id : int
        1..K among the groups written.
    facets : (F, d) ndarray of intp
        Corner node ids, oriented out of `owner` in the files' frame.
    owner : (F,) ndarray of intp
        Element (0-based row of the mesh) each facet bounds.
    corner : (F,) ndarray of intp
        The owner's corner opposite the facet, in the cell as written.
    """

    id: int
    facets: np.ndarray
    owner: np.ndarray
    corner: np.ndarray


class ExportMesh:
    """A `Mesh` ready to write: points and cells in the files' frame, order, facet groups.

    Parameters
    ----------
    mesh : Mesh
    order : {1, 2}
    groups : "all", "none" or tuple of str
        As returned by :func:`check_facet_selection`.
    """

    def __init__(self, mesh: Mesh, *, order: int = 1, groups="all"):
        self.mesh = mesh
        self.ndim = mesh.ndim
        self.order = order
        corners = export_points(mesh)                              # (N, d)
        self.n_corners = len(corners)
        # the leaf path of the facet groups gives the volumes' signs on the way (its
        # corner gathers are most of the cost of either)
        found, negative = ({}, None) if groups == "none" else groups_and_signs(
            mesh, signs=True, facets=False)
        if negative is not None:
            # one affine map from the points to the files' frame turns every cell alike
            self.flip = negative ^ export_turns(mesh)
        else:
            # (M,) swap corners 0 and 1; in slices, so the corner coordinates of a slice
            # are all the memory it takes (gathered axis by axis: a row gather of (N, d)
            # points took most of the time)
            axes = [np.ascontiguousarray(corners[:, a]) for a in range(self.ndim)]
            self.flip = np.empty(mesh.n_cells, dtype=bool)
            for start in range(0, mesh.n_cells, _SLICE):
                block = mesh.cells[start:start + _SLICE]
                det = _corner_det([[x[block[:, k]] for x in axes]
                                   for k in range(self.ndim + 1)])
                np.less(det, 0, out=self.flip[start:start + len(block)])
            del axes
        self.any_flip = bool(self.flip.any())
        self.edges = MidEdges(mesh.cells, len(corners)) if order == 2 else None
        self.points = (corners if self.edges is None
                       else np.concatenate([corners, self.edges.midpoints(corners)]))
        self.material = np.asarray(mesh.material, dtype=np.int64)
        self.names = material_names(mesh.material_names, present_materials(self.material))
        chosen = select_facet_groups(found, groups) if groups != "none" else {}
        self.groups = {name: self._in_file_frame(k + 1, g)
                       for k, (name, g) in enumerate(chosen.items())}

    @property
    def n_cells(self) -> int:
        return self.mesh.n_cells

    @property
    def nodes_per_cell(self) -> int:
        d = self.ndim
        return d + 1 if self.order == 1 else (d + 1) * (d + 2) // 2

    def cells(self, rows=slice(None), family: str = "vtk") -> np.ndarray:
        """Cells `rows` as written: positive in the files' frame, mid-edge nodes after the
        corners in `family`'s order (see ``_order2``)."""
        return with_mid_nodes(self._corners(rows), self.edges, family)

    def all_cells(self, family: str = "vtk") -> np.ndarray:
        """Every cell as :meth:`cells` gives it, filled block by block into one array (no
        temporaries of the whole mesh)."""
        out = np.empty((self.n_cells, self.nodes_per_cell), dtype=np.intp)
        for start in range(0, self.n_cells, _SLICE):
            out[start:start + _SLICE] = self.cells(slice(start, start + _SLICE), family)
        return out

    def cell_blocks(self, family: str = "vtk") -> CellBlocks:
        """Every cell as :meth:`cells` gives it, block by block for a streaming writer."""
        return CellBlocks(self.n_cells, self.nodes_per_cell,
                          lambda start, stop: self.cells(slice(start, stop), family))

    def _corners(self, rows) -> np.ndarray:
        cells = np.array(self.mesh.cells[rows], dtype=np.intp, copy=True)
        if not self.any_flip:
            return cells
        flip = self.flip[rows]
        # a masked copy: boolean fancy indexing of the columns took twice as long
        first = cells[:, 0].copy()
        np.copyto(cells[:, 0], cells[:, 1], where=flip)
        np.copyto(cells[:, 1], first, where=flip)
        return cells

    def facet_nodes(self, group: FileFacets) -> np.ndarray:
        """The facets of `group` with their mid-edge nodes (second order) after the corners."""
        return with_mid_nodes(group.facets, self.edges, "vtk")

    def _in_file_frame(self, gid: int, group) -> FileFacets:
        owner = np.asarray(group.owner, dtype=np.intp)
        corner = np.array(group.opposite, dtype=np.intp, copy=True)
        swapped = self.flip[owner] & (corner < 2)
        corner[swapped] = 1 - corner[swapped]
        # the face opposite `corner` of the cell as written (positive in the files'
        # frame), by FACE_CORNERS: oriented out of it
        facets = self._corners(owner)[np.arange(len(owner))[:, None],
                                   FACE_CORNERS[self.ndim][corner]]
        return FileFacets(gid, facets, owner, corner)
