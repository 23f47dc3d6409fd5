"""The facet groups of a ``.vtu`` or ``.xdmf`` mesh, in a companion ``.vtu`` beside it.

The companion of ``<stem>.vtu`` is ``<stem>_facets.vtu``, that of ``<stem>.xdmf`` is
``<stem>_xdmf_facets.vtu`` (so the two formats of one mesh can lie side by side).

The companion holds the same points as the mesh file, in the same order (so a facet's
nodes are node ids of the mesh), and one cell per facet: lines in 2-D, triangles in 3-D
(3-node lines and 6-node triangles at second order), oriented out of the element that
owns them. Cell data: ``group`` (int32, the group id 1..K) and ``owner`` (the 0-based
element of the mesh file that the facet bounds; on an interface, the element of the
lower-labelled material; Int32 in the file below 2**31 elements, else Int64). The names
ride in ``<FieldData>``: one one-value array per group, named after the group and holding
its id (VTK's field data; meshio reads them as ``field_data``, pyvista as
``grid.field_data``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._vtu import write_vtu

__all__ = ["facets_companion", "write_facets_vtu", "FACETS_STEM"]

FACETS_STEM = "_facets"
#: VTK cell type of the facets by (dimension of the mesh, order).
_VTK_FACET = {(2, 1): 3, (2, 2): 21, (3, 1): 5, (3, 2): 22}


def facets_companion(path) -> Path:
    """The facets file beside mesh file `path`: ``<stem>_facets.vtu`` for a ``.vtu``,
    ``<stem>_<format>_facets.vtu`` for any other format (the two never collide).

    Examples
    --------
    >>> facets_companion("out/brain.vtu").as_posix()
    'out/brain_facets.vtu'
    >>> facets_companion("out/brain.xdmf").as_posix()
    'out/brain_xdmf_facets.vtu'
    """
    p = Path(path)
    kind = p.suffix.lower().lstrip(".")
    middle = "" if kind == "vtu" else f"_{kind}"
    return p.with_name(f"{p.stem}{middle}{FACETS_STEM}.vtu")


def write_facets_vtu(ex, path) -> None:
    """Write the facet groups of `ex` (an ``_prepare.ExportMesh``) to `path`."""
    groups = list(ex.groups.items())
    width = ex.ndim if ex.order == 1 else 3 * ex.ndim - 3        # 2, 3 / 3, 6 nodes
    nodes = np.concatenate([np.zeros((0, width), np.intp)]
                           + [ex.facet_nodes(g) for _, g in groups])
    group = np.concatenate([np.zeros(0, np.int32)]
                           + [np.full(len(g.owner), g.id, np.int32) for _, g in groups])
    owner = np.concatenate([np.zeros(0, np.int64)] + [g.owner for _, g in groups])
    write_vtu(path, ex.points, nodes, cell_data={"group": group, "owner": owner},
              field_data={name: [g.id] for name, g in groups},
              cell_type=_VTK_FACET[(ex.ndim, ex.order)])
