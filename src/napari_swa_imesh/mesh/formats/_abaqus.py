"""Abaqus ``.inp``, written by our own streaming writer with what CalculiX and FE users need.

* ``*NODE`` (2 or 3 coordinates; mid-edge nodes after the corners at second order) and
  one ``*ELEMENT`` block, element ids 1..M in the mesh's order.
* One ``*ELSET`` per material, named after it and made a valid Abaqus label (start with
  a letter; letters, digits, underscores; at most 80 characters): ``soft tissue`` ->
  ``soft_tissue``.
* Element types (:data:`ABAQUS_ELEMENTS`): continuum ``CPS3``/``C3D4`` (``CPS6``/``C3D10``
  at second order, mid-edge nodes in the element's edge order 12 23 31 (14 24 34)), or
  for ``*HEAT TRANSFER`` ``DC2D3``/``DC3D4`` (``DC2D6``/``DC3D10``).
* Material ids ride along as comment lines on top, ``** swa-imesh material <id> <set>``,
  so reading recovers them (sets named ``material_<id>`` are understood too).
* Numbers with 13 significant digits, so every field fits the 20 characters CalculiX (the
  common free reader) takes; longer fields are rejected there. Integers are right-aligned
  with blanks to the widest of their column in a block of lines (Abaqus and CalculiX skip
  blanks in data lines), so that numpy makes the text of a whole block at once
  (:mod:`._text`).
* The facet groups (:func:`~napari_swa_imesh.mesh.facet_groups`: ``xmin`` ... ``zmax``,
  ``interface_<A>_<B>``, ``exterior_<A>``) as a ``*NSET`` of their nodes (mid-edge nodes
  included at second order; for ``*BOUNDARY``) and an element-face ``*SURFACE`` (for
  ``*DSLOAD``, ``*DFLUX``, ``*FILM``), built from ``*ELSET``s ``<group>_S<k>`` of the
  elements whose face k it is (second-order elements number their faces as the linear).

Every table is written in blocks of rows (no text of the whole file). The format has no
per-cell arrays, so quality and angles are not written.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ._triangle_tetgen import write_rows

__all__ = ["write_abaqus", "abaqus_materials", "ABAQUS_ELEMENTS", "FACE_NUMBER"]

#: Element type per analysis, then per (dimension, order): continuum mechanics, or heat
#: transfer (``*HEAT TRANSFER``).
ABAQUS_ELEMENTS = {
    "mechanical": {(2, 1): "CPS3", (3, 1): "C3D4", (2, 2): "CPS6", (3, 2): "C3D10"},
    "heat": {(2, 1): "DC2D3", (3, 1): "DC3D4", (2, 2): "DC2D6", (3, 2): "DC3D10"},
}
#: Abaqus face number (S1..) of the face opposite corner k (0-based) of a triangle
#: (S1 = nodes 1-2, S2 = 2-3, S3 = 3-1) or a tetrahedron (S1 = 1-2-3, S2 = 1-4-2,
#: S3 = 2-4-3, S4 = 3-4-1).
FACE_NUMBER = {2: np.array([2, 3, 1]), 3: np.array([3, 4, 2, 1])}
_NAME_NOTE = "** swa-imesh material"  # comment line: "<note> <id> <set name>"
_ROWS = 1 << 16


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


def _write_ids(fh, ids: np.ndarray) -> None:
    """0-based `ids` as 1-based, 16 to a line (the Abaqus limit for data lines), or 8 past
    10**8 (their fields may be 16 digits wide: lines stay within Abaqus's 256 characters)."""
    ids = np.asarray(ids, dtype=np.int64) + 1
    per_line = 16 if not len(ids) or ids.max() < 10 ** 8 else 8
    full = len(ids) // per_line * per_line
    write_rows(fh, ids[:full].reshape(-1, per_line), sep=", ")
    if full < len(ids):
        fh.write(", ".join(map(str, ids[full:].tolist())) + "\n")


def _write_facet_sets(fh, ex) -> None:
    """``*NSET``, ``*ELSET`` and ``*SURFACE`` keywords of the facet groups of `ex`."""
    labels = _set_names({g.id: name for name, g in ex.groups.items()})
    for g in ex.groups.values():
        name = labels[g.id]
        fh.write(f"*NSET, NSET={name}\n")
        _write_ids(fh, np.unique(ex.facet_nodes(g)))
        face = FACE_NUMBER[ex.ndim][g.corner]
        surface = [f"*SURFACE, NAME={name}, TYPE=ELEMENT\n"]
        for number in np.unique(face):
            fh.write(f"*ELSET, ELSET={name}_S{number}\n")
            _write_ids(fh, np.sort(g.owner[face == number]))
            surface.append(f"{name}_S{number}, S{number}\n")
        fh.write("".join(surface))


def write_abaqus(ex, path, *, elements: str = "mechanical") -> None:
    """Write `ex` (an ``_prepare.ExportMesh``) as Abaqus ``.inp`` with the element types of
    `elements` (a key of :data:`ABAQUS_ELEMENTS`)."""
    set_names = _set_names(ex.names)
    element = ABAQUS_ELEMENTS[elements][(ex.ndim, ex.order)]
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("".join(f"{_NAME_NOTE} {mat} {name}\n" for mat, name in set_names.items()))
        fh.write("*HEADING\nwritten by napari-swa-imesh\n*NODE\n")
        n = len(ex.points)
        for start in range(0, n, _ROWS):
            block = ex.points[start:start + _ROWS]
            write_rows(fh, np.arange(start + 1, start + len(block) + 1)[:, None], block,
                       sep=", ", float_format="%.12e")
        fh.write(f"*ELEMENT, TYPE={element}\n")
        for start in range(0, ex.n_cells, _ROWS):
            cells = ex.cells(slice(start, start + _ROWS)) + 1
            write_rows(fh, np.column_stack([np.arange(start + 1, start + len(cells) + 1),
                                            cells]), sep=", ")
        for mat, name in set_names.items():
            fh.write(f"*ELSET, ELSET={name}\n")
            _write_ids(fh, np.flatnonzero(ex.material == mat))
        _write_facet_sets(fh, ex)


def abaqus_materials(path: Path, m, keep: list[int], n_cells: int):
    """Material names and ids of an ``.inp`` read by meshio (cells of blocks `keep`).

    Ids come from our comment lines (and then only the noted sets are materials: the
    others hold facet groups), else from ``material_<id>`` set names, else 1..K in the
    order of the sets. Returns ``(names, material (n_cells,) int64)``, or ``({}, None)``
    for a file without sets or notes (no materials).
    """
    ids: dict[str, int] = {}
    with open(path) as fh:
        for line in fh:
            if not line.startswith("**"):
                break
            if line.startswith(_NAME_NOTE):
                number, name = line[len(_NAME_NOTE) :].split()
                ids[name] = int(number)
    if not ids and not m.cell_sets:
        return {}, None
    material = np.zeros(n_cells, dtype=np.int64)
    names: dict[int, str] = {}
    offsets = np.cumsum([0] + [len(m.cells[i].data) for i in keep])
    sets = m.cell_sets.items()
    if ids:                       # our file: the noted sets are the materials, the rest
        sets = [(name, blocks) for name, blocks in sets if name in ids]   # are facet sets
    covered = np.zeros(n_cells, dtype=bool)
    for k, (name, blocks) in enumerate(sets):
        found = re.fullmatch(r"material_(\d+)", name)
        mat = ids.get(name, int(found.group(1)) if found else k + 1)
        names[mat] = name
        for j, i in enumerate(keep):
            at = offsets[j] + np.asarray(blocks[i], dtype=np.intp)
            material[at], covered[at] = mat, True
    # our files note every material set and put every element in one: a file cut short
    # (a line-based format, so meshio reads what is left) lacks sets or elements of them
    lost = sorted(set(ids) - {name for name, _ in sets})
    if ids and (lost or not covered.all()):
        what = (f"its material set(s) {', '.join(lost)} are missing" if lost else
                f"{int((~covered).sum())} of its {n_cells} elements are in no material set")
        raise ValueError(f"cannot read {path} as a .inp mesh: the file is truncated or "
                         f"damaged ({what}); write it again (or copy it again in full).")
    return names, material
