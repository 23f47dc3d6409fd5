"""Abaqus ``.inp`` through meshio, with the fixes CalculiX and FE users need.

* One ``*ELSET`` per material, named after it and made a valid Abaqus label (start with
  a letter; letters, digits, underscores; at most 80 characters): ``soft tissue`` ->
  ``soft_tissue``.
* Element types: meshio names triangles ``R3D3`` (a rigid surface); a 2-D solid wants the
  continuum ``CPS3``, tetrahedra are ``C3D4``.
* Material ids ride along as comment lines on top, ``** swa-imesh material <id> <set>``,
  so reading recovers them (sets named ``material_<id>`` are understood too).
* Numbers with 13 significant digits, so every field fits the 20 characters CalculiX (the
  common free reader) takes; longer fields are rejected there.

The format has no per-cell arrays, so quality and angles are not written.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ._common import material_names

__all__ = ["write_abaqus", "abaqus_materials", "ABAQUS_TYPE"]

#: Element type per dimension.
ABAQUS_TYPE = {2: "CPS3", 3: "C3D4"}
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


def write_abaqus(names: dict[int, str], m, path: str) -> None:
    """Write `m` as Abaqus ``.inp`` (arguments: see ``_common``, "Format writers")."""
    import meshio

    material = m.cell_data["material"][0]
    materials = np.unique(material)
    set_names = _set_names(material_names(names, materials))
    cell_sets = {set_names[int(mat)]: [np.flatnonzero(material == mat)] for mat in materials}
    out = meshio.Mesh(m.points, m.cells, cell_sets=cell_sets)
    meshio.write(path, out, file_format="abaqus", float_fmt=".12e")
    text = Path(path).read_text()
    element = ABAQUS_TYPE[m.points.shape[1]]
    text = re.sub(r"(?im)^\*ELEMENT, TYPE=\w+$", f"*ELEMENT, TYPE={element}", text)
    notes = "".join(f"{_NAME_NOTE} {mat} {name}\n" for mat, name in set_names.items())
    Path(path).write_text(notes + text)


def abaqus_materials(path: Path, m, keep: list[int], n_cells: int):
    """Material names and ids of an ``.inp`` read by meshio (cells of blocks `keep`).

    Ids come from our comment lines, else from ``material_<id>`` set names, else 1..K in
    the order of the sets. Returns ``(names, material (n_cells,) int64)``.
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
    for k, (name, blocks) in enumerate(m.cell_sets.items()):
        found = re.fullmatch(r"material_(\d+)", name)
        mat = ids.get(name, int(found.group(1)) if found else k + 1)
        names[mat] = name
        for j, i in enumerate(keep):
            material[offsets[j] + np.asarray(blocks[i], dtype=np.intp)] = mat
    return names, material
