"""Gmsh 4.1 ``.msh`` through meshio, with the two workarounds it needs.

* Physical groups: one cell block, one entity and one named physical group per material
  (tag = material id; material 0 gets ``max + 1``, Gmsh tags being positive). Gmsh 4 keeps
  physical tags on entities and meshio writes an entity only if some node is classified
  on it, so every material gets a node of its own by a maximum bipartite matching.
* Element data: meshio 5.3 writes ASCII ``$ElementData`` with ``repr``, which numpy 2
  turns into ``np.float64(...)``, so those sections are appended here.

Element tags run 1..M through the material blocks in order; reading gives the cells back
in that order (grouped by material).
"""

from __future__ import annotations

import numpy as np

from ._common import CELL_TYPE, material_names
from ._triangle_tetgen import format_rows

__all__ = ["write_gmsh", "gmsh_materials"]


def _gmsh_tags(materials: np.ndarray) -> dict[int, int]:
    """Physical tag per material: its id, except 0 (Gmsh tags are positive) -> max+1."""
    top = int(materials.max())
    return {int(m): (int(m) if m > 0 else top + 1) for m in materials}


def _tagged_mesh(names: dict[int, str], m):
    """One cell block, entity and named physical group per material.

    Returns the tagged meshio mesh and the per-cell arrays in its cell order.
    """
    import meshio
    import scipy.sparse as sp
    from scipy.sparse.csgraph import maximum_bipartite_matching

    cells = m.cells[0].data
    dim = m.points.shape[1]
    material = m.cell_data["material"][0]
    materials = np.unique(material)
    names = material_names(names, materials)
    tags = _gmsh_tags(materials)
    blocks = [material == mat for mat in materials]

    # one entity per material, tagged like its physical group
    block_tags = [np.full(b.sum(), tags[int(mat)]) for mat, b in zip(materials, blocks)]
    cell_data = {"gmsh:physical": block_tags, "gmsh:geometrical": block_tags}
    field_data = {names[int(mat)]: np.array([tags[int(mat)], dim]) for mat in materials}

    # every material block needs a node of its own: a maximum bipartite matching
    # (blocks x nodes) finds one for each
    n_points = len(m.points)
    block_of_cell = np.searchsorted(materials, material)  # (M,)
    incidence = sp.csr_matrix(
        (np.ones(cells.size, dtype=np.int8),
         (np.repeat(block_of_cell, cells.shape[1]), cells.ravel())),
        shape=(len(materials), n_points),
    )
    owner = maximum_bipartite_matching(incidence, perm_type="column")  # (K,) node or -1
    if (owner < 0).any():
        raise ValueError(
            "cannot write Gmsh 4.1 physical groups: some materials have too few nodes of "
            "their own to be told apart; write .vtu or .xdmf instead."
        )
    node_block = np.zeros(n_points, dtype=np.intp)
    node_block[cells.ravel()] = np.repeat(block_of_cell, cells.shape[1])
    node_block[owner] = np.arange(len(materials))
    entity_of_block = np.array([tags[int(mat)] for mat in materials])
    dim_tags = np.column_stack([np.full(n_points, dim), entity_of_block[node_block]])

    tagged = meshio.Mesh(
        m.points,
        [(CELL_TYPE[dim], cells[b]) for b in blocks],
        cell_data=cell_data,
        point_data={"gmsh:dim_tags": dim_tags},
        field_data=field_data,
    )
    # element tags run 1..M through the blocks in order, so the data follow that order
    order = np.concatenate([np.flatnonzero(b) for b in blocks])
    element_data = {key: values[0][order] for key, values in m.cell_data.items()}
    return tagged, element_data


def _append_element_data(path: str, element_data: dict[str, np.ndarray]) -> None:
    """Append one ``$ElementData`` section per array (1 component, time step 0)."""
    with open(path, "a") as fh:
        for name, values in element_data.items():
            values = np.asarray(values)
            fh.write(f'$ElementData\n1\n"{name}"\n1\n0.0\n3\n0\n1\n{len(values)}\n')
            tags = np.arange(1, len(values) + 1)[:, None]
            if values.dtype.kind in "iu":
                fh.write(format_rows(np.column_stack([tags, values])))
            else:
                fh.write(format_rows(tags, values[:, None]))
            fh.write("$EndElementData\n")


def write_gmsh(names: dict[int, str], m, path: str) -> None:
    """Write `m` as ASCII Gmsh 4.1 (arguments: see ``_common``, "Format writers")."""
    import meshio

    tagged, element_data = _tagged_mesh(names, m)
    meshio.write(path, tagged, file_format="gmsh", binary=False)
    _append_element_data(path, element_data)


def gmsh_materials(m, keep: list[int]):
    """Material names and (from physical tags) material ids of a Gmsh file read by meshio.

    Returns ``(names, material)``: ``material`` is None when the file has no physical
    groups; names map material ids to group names.
    """
    if "gmsh:physical" not in m.cell_data:
        return {}, None
    physical = np.concatenate([m.cell_data["gmsh:physical"][i] for i in keep]).astype(np.int64)
    material_of_cell = m.cell_data.get("material")
    tag_to_name = {int(tag): name for name, (tag, _dim) in m.field_data.items()}
    names: dict[int, str] = {}
    if material_of_cell is not None:
        material = np.concatenate([material_of_cell[i] for i in keep]).astype(np.int64)
        for tag in np.unique(physical):
            ids = np.unique(material[physical == tag])
            if len(ids) == 1 and int(tag) in tag_to_name:
                names[int(ids[0])] = tag_to_name[int(tag)]
        return names, material
    for tag, name in tag_to_name.items():
        names[tag] = name
    return names, physical
