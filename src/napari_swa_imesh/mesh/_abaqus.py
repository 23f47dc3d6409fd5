"""Abaqus ``.inp`` through meshio, with the fixes CalculiX and FE users need.

* One ``*ELSET`` per material, named after it and made a valid Abaqus label (start with
  a letter; letters, digits, underscores; at most 80 characters): ``soft tissue`` ->
  ``soft_tissue``.
* Element types: meshio names triangles ``R3D3`` (a rigid surface); a 2-D solid wants the
  continuum ``CPS3``, tetrahedra are ``C3D4``; for heat transfer ``DC2D3``/``DC3D4``.
* Material ids ride along as comment lines on top, ``** swa-imesh material <id> <set>``,
  so reading recovers them (sets named ``material_<id>`` are understood too).
* Numbers with 13 significant digits, so every field fits the 20 characters CalculiX (the
  common free reader) takes; longer fields are rejected there.
* The facet groups (:func:`~napari_swa_imesh.mesh.facet_groups`: ``xmin`` ... ``zmax``,
  ``interface_<A>_<B>``, ``exterior_<A>``) as a ``*NSET`` of their nodes (for
  ``*BOUNDARY``) and an element-face ``*SURFACE`` (for ``*DSLOAD``, ``*DFLUX``, ``*FILM``),
  built from ``*ELSET``s ``<group>_S<k>`` of the elements whose face k it is.

The format has no per-cell arrays, so quality and angles are not written.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ._common import material_names

__all__ = ["write_abaqus", "abaqus_materials", "facet_sets_text", "ABAQUS_ELEMENTS",
           "ABAQUS_TYPE", "FACE_NUMBER"]

#: Element type per dimension.
ABAQUS_TYPE = {2: "CPS3", 3: "C3D4"}
#: Element types per analysis: continuum mechanics, or heat transfer (``*HEAT TRANSFER``).
ABAQUS_ELEMENTS = {"mechanical": ABAQUS_TYPE, "heat": {2: "DC2D3", 3: "DC3D4"}}
#: Abaqus face number (S1..) of the face opposite corner k (0-based) of a triangle
#: (S1 = nodes 1-2, S2 = 2-3, S3 = 3-1) or a tetrahedron (S1 = 1-2-3, S2 = 1-4-2,
#: S3 = 2-4-3, S4 = 3-4-1).
FACE_NUMBER = {2: np.array([2, 3, 1]), 3: np.array([3, 4, 2, 1])}
_NAME_NOTE = "** swa-imesh material"  # comment line: "<note> <id> <set name>"


def _set_names(names: dict[int, str]) -> dict[int, str]:
    """Abaqus labels: start with a letter, letters/digits/underscores, at most 80 chars."""
    out: dict[int, str] = {}
    for m, name in names.items():
        label = re.sub(r"[^A-Za-z0-9_]", "_", name.strip())
        if not label[0].isalpha():
            label = "M_" + label
        label = label[:80]
        if label in out.values():
            label = f"{label[:70]}_{m}"
        out[m] = label
    return out


def _id_lines(ids: np.ndarray) -> str:
    """1-based ids, 16 to a line (the Abaqus limit for data lines)."""
    ids = np.asarray(ids) + 1
    return "".join(", ".join(map(str, ids[i:i + 16])) + "\n" for i in range(0, len(ids), 16))


def facet_sets_text(groups: dict, cells_written: np.ndarray, cells_mesh: np.ndarray) -> str:
    """``*NSET``, ``*ELSET`` and ``*SURFACE`` keywords of the facet groups.

    Parameters
    ----------
    groups : dict of str to FacetGroup
        From :func:`facet_groups` on the mesh.
    cells_written : (M, d+1) ndarray
        The cells as written (corners 0 and 1 may have been swapped to keep the volume
        positive in x, y(, z) order), which fixes the face numbers.
    cells_mesh : (M, d+1) ndarray
        The mesh's own cells, in which the groups' corners are counted.
    """
    d = cells_mesh.shape[1] - 1
    swapped = cells_written[:, 0] != cells_mesh[:, 0]
    labels = _set_names({i: name for i, name in enumerate(groups)})
    out = []
    for i, group in enumerate(groups.values()):
        name = labels[i]
        out.append(f"*NSET, NSET={name}\n{_id_lines(np.unique(group.facets))}")
        corner = group.opposite.copy()
        flip = swapped[group.owner] & (corner < 2)
        corner[flip] = 1 - corner[flip]
        face = FACE_NUMBER[d][corner]
        surface = [f"*SURFACE, NAME={name}, TYPE=ELEMENT\n"]
        for number in np.unique(face):
            elements = np.sort(group.owner[face == number])
            out.append(f"*ELSET, ELSET={name}_S{number}\n{_id_lines(elements)}")
            surface.append(f"{name}_S{number}, S{number}\n")
        out.append("".join(surface))
    return "".join(out)


def write_abaqus(names: dict[int, str], m, path: str, *, groups: dict | None = None,
                 cells_mesh: np.ndarray | None = None, elements: str = "mechanical") -> None:
    """Write `m` as Abaqus ``.inp`` (arguments: see ``_common``, "Format writers"), with
    the facet `groups` of the mesh whose own cells are `cells_mesh`, and the element
    types of `elements` (a key of :data:`ABAQUS_ELEMENTS`)."""
    import meshio

    material = m.cell_data["material"][0]
    materials = np.unique(material)
    set_names = _set_names(material_names(names, materials))
    cell_sets = {set_names[int(mat)]: [np.flatnonzero(material == mat)] for mat in materials}
    out = meshio.Mesh(m.points, m.cells, cell_sets=cell_sets)
    meshio.write(path, out, file_format="abaqus", float_fmt=".12e")
    text = Path(path).read_text()
    element = ABAQUS_ELEMENTS[elements][m.points.shape[1]]
    text = re.sub(r"(?im)^\*ELEMENT, TYPE=\w+$", f"*ELEMENT, TYPE={element}", text)
    notes = "".join(f"{_NAME_NOTE} {mat} {name}\n" for mat, name in set_names.items())
    if groups:
        text = text.rstrip("\n") + "\n" + facet_sets_text(groups, m.cells[0].data, cells_mesh)
    Path(path).write_text(notes + text)


def abaqus_materials(path: Path, m, keep: list[int], n_cells: int):
    """Material names and ids of an ``.inp`` read by meshio (cells of blocks `keep`).

    Ids come from our comment lines (and then only the noted sets are materials: the
    others hold facet groups), else from ``material_<id>`` set names, else 1..K in the
    order of the sets. Returns ``(names, material (n_cells,) int64)``.
    """
    ids: dict[str, int] = {}
    with open(path) as fh:
        for line in fh:
            if not line.startswith("**"):
                break
            if line.startswith(_NAME_NOTE):
                mat, name = line[len(_NAME_NOTE) :].split()
                ids[name] = int(mat)
    material = np.zeros(n_cells, dtype=np.int64)
    names: dict[int, str] = {}
    offsets = np.cumsum([0] + [len(m.cells[i].data) for i in keep])
    sets = m.cell_sets.items()
    if ids:                       # our file: the noted sets are the materials, the rest
        sets = [(name, blocks) for name, blocks in sets if name in ids]   # are facet sets
    for k, (name, blocks) in enumerate(sets):
        found = re.fullmatch(r"material_(\d+)", name)
        mat = ids.get(name, int(found.group(1)) if found else k + 1)
        names[mat] = name
        for j, i in enumerate(keep):
            material[offsets[j] + np.asarray(blocks[i], dtype=np.intp)] = mat
    return names, material
