"""Gmsh 4.1 ``.msh``, binary (default) or ASCII, written by our own streaming writer.

Layout (Gmsh reference manual, "MSH file format", version 4.1)
----------------------------------------------------------------
* ``$PhysicalNames`` (always text): one group of dimension d per material named after it
  (tag = material id; material 0 gets ``max + 1``, Gmsh tags being positive 32-bit
  integers; when some id does not fit so, negative ones or ids from 2^31 on, every
  material gets its rank 1..K instead, and only the name, by default ``material_<id>``,
  and the ``material`` element data tell the id), and one group of dimension d-1 per
  facet group written (tag = its id 1..K), named after it.
* ``$Entities``: one entity per physical group, with the same dimension and tag (entity
  and physical tags count per dimension), the mesh's bounding box and no bounding
  entities.
* ``$Nodes``: every node in one block (on the first material's entity): tags 1..N in the
  mesh's point order, then the mid-edge nodes (second order). Elements of other
  entities refer to them by tag, which the format allows.
* ``$Elements``: the elements grouped by material (one block each, tags 1..M in that
  order), then one block of facet elements per facet group (tags M+1..); types 2/4
  (triangle, tetrahedron) with 1 (line) for facets, or at second order 9/11 with 8
  (3-node line) and 9 (6-node triangle) for facets. Facets are oriented out of their
  owner element.
* ``$ElementData``: ``material`` and every per-cell array, one component, for every
  element; a facet element carries the values of its owner (meshio reads element data
  only when it covers every element). Element data are doubles: material ids beyond
  2^53 in size would be rounded, so they are refused (:func:`check_gmsh_labels`).

Binary sections hold the same numbers as native ``int`` (4 bytes), ``size_t`` (8) and
``double``; the ``1`` after the format line tells readers the byte order. Everything is
written in blocks of rows, so memory stays at a block beyond the mesh.
"""

from __future__ import annotations

import numpy as np

from ..checks._leaf_facets import material_codes
from ._triangle_tetgen import write_rows

__all__ = ["write_gmsh", "gmsh_materials", "gmsh_tags", "check_gmsh_labels", "GMSH_TYPE"]

#: (nodes per element) -> Gmsh element type: line, triangle, tetrahedron; 3-node line,
#: 6-node triangle, 10-node tetrahedron.
GMSH_TYPE = {2: 1, 3: 2, 4: 4, 6: 9, 10: 11}
_LINE3 = 8                          # 3 nodes: a line of order 2, not a triangle
_ROWS = 1 << 16
_SIZE_T, _INT = np.dtype(np.uint64), np.dtype(np.int32)


_TAG_MAX = 2**31 - 1                # Gmsh tags are C ints
_EXACT = 2**53                      # element data are doubles


def gmsh_tags(materials: np.ndarray) -> dict[int, int]:
    """Physical tag per material (sorted ids): its id, 0 -> max+1 (Gmsh tags are
    positive), when every tag then fits a 32-bit int; else its rank 1..K.

    Examples
    --------
    >>> gmsh_tags(np.array([0, 3, 7]))
    {0: 8, 3: 3, 7: 7}
    >>> gmsh_tags(np.array([-2, 0, 2**40]))
    {-2: 1, 0: 2, 1099511627776: 3}
    """
    ids = [int(m) for m in materials]
    top = max(ids)
    if min(ids) >= 0 and top + (0 in ids) <= _TAG_MAX:
        return {m: (m if m > 0 else top + 1) for m in ids}
    return {m: k + 1 for k, m in enumerate(sorted(ids))}


def check_gmsh_labels(labels: np.ndarray, exclude=()) -> None:
    """Raise ValueError unless the material ids in `labels` (those not in `exclude`) are
    exact in ``.msh`` element data (doubles: up to 2^53 in size)."""
    lo, hi = (int(labels.min()), int(labels.max())) if labels.size else (0, 0)
    if max(abs(lo), abs(hi)) <= _EXACT:
        return
    if len(exclude):                    # rare: only labels this large pay for the unique
        kept = np.setdiff1d(np.unique(labels), np.asarray(exclude, dtype=np.int64))
        lo, hi = (int(kept.min()), int(kept.max())) if kept.size else (0, 0)
        if max(abs(lo), abs(hi)) <= _EXACT:
            return
    raise ValueError(
        f"Gmsh .msh keeps material ids as doubles in its element data, exact up to 2^53, "
        f"but the labels span {lo} .. {hi}; relabel them (for example 1..K) or write "
        ".vtu or .xdmf, which keep 64-bit labels.")


class _Out:
    """Writes numbers as binary or as text lines to one open (binary) file."""

    def __init__(self, fh, binary: bool):
        self.fh, self.binary = fh, binary

    def text(self, s: str) -> None:
        self.fh.write(s.encode())

    def row(self, *values, dtypes) -> None:
        """One record of mixed types (e.g. int, int, int, size_t), one text line."""
        if self.binary:
            for v, dt in zip(values, dtypes):
                self.fh.write(np.asarray(v, dtype=dt).tobytes())
        else:
            self.text(" ".join(_fmt(v) for v in values) + "\n")

    def table(self, table: np.ndarray, dtype, floats: bool = False) -> None:
        """Rows of one type: binary as they are, text one row a line."""
        if self.binary:
            for start in range(0, len(table), _ROWS):
                self.fh.write(np.ascontiguousarray(table[start:start + _ROWS], dtype).tobytes())
        elif floats:
            write_rows(self.fh, np.zeros((len(table), 0), np.int64), table, encode=True)
        else:
            write_rows(self.fh, table, encode=True)

    def end(self, section: str) -> None:
        self.text(f"\n$End{section}\n" if self.binary else f"$End{section}\n")


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if np.ndim(v):
        return " ".join(_fmt(x) for x in np.ravel(v))
    return str(int(v))


def write_gmsh(ex, path, *, binary: bool = True) -> None:
    """Write `ex` (an ``_prepare.ExportMesh``) as Gmsh 4.1 to `path`."""
    d = ex.ndim
    materials, code = material_codes(ex.material)
    check_gmsh_labels(materials)
    tags = gmsh_tags(materials)
    order = np.argsort(code, kind="stable")     # (M,) by material: a radix sort of ranks
    bounds = np.searchsorted(ex.material[order], materials, side="left")
    bounds = np.append(bounds, len(order))
    lo, hi = ex.points.min(axis=0), ex.points.max(axis=0)
    box = np.concatenate([np.pad(lo, (0, 3 - d)), np.pad(hi, (0, 3 - d))])

    with open(path, "wb") as fh:
        out = _Out(fh, binary)
        out.text(f"$MeshFormat\n4.1 {int(binary)} 8\n")
        if binary:
            fh.write(np.array([1], _INT).tobytes() + b"\n")
        out.text("$EndMeshFormat\n")

        names = [f'{d} {tags[int(m)]} "{ex.names[int(m)]}"' for m in materials]
        names += [f'{d - 1} {g.id} "{name}"' for name, g in ex.groups.items()]
        out.text(f"$PhysicalNames\n{len(names)}\n" + "".join(n + "\n" for n in names)
                 + "$EndPhysicalNames\n")

        out.text("$Entities\n")
        counts = [0, 0, 0, 0]
        counts[d], counts[d - 1] = len(materials), len(ex.groups)
        out.row(*counts, dtypes=[_SIZE_T] * 4)
        entities = sorted([(d - 1, g.id) for g in ex.groups.values()]
                          + [(d, tags[int(m)]) for m in materials])
        for _, tag in entities:                                        # by dimension
            out.row(tag, box, 1, tag, 0, dtypes=[_INT, np.float64, _SIZE_T, _INT, _SIZE_T])
        out.end("Entities")

        n = len(ex.points)
        out.text("$Nodes\n")
        out.row(1, n, 1, n, dtypes=[_SIZE_T] * 4)
        out.row(d, tags[int(materials[0])], 0, n, dtypes=[_INT, _INT, _INT, _SIZE_T])
        for start in range(0, n, _ROWS):
            out.table(np.arange(start + 1, min(n, start + _ROWS) + 1)[:, None], _SIZE_T)
        for start in range(0, n, _ROWS):
            block = ex.points[start:start + _ROWS]
            out.table(np.pad(block, ((0, 0), (0, 3 - d))), np.float64, floats=True)
        out.end("Nodes")

        n_facets = sum(len(g.owner) for g in ex.groups.values())
        total = ex.n_cells + n_facets
        out.text("$Elements\n")
        out.row(len(materials) + len(ex.groups), total, 1, total, dtypes=[_SIZE_T] * 4)
        kind = GMSH_TYPE[ex.nodes_per_cell]
        tag = 1
        for k, m in enumerate(materials):
            rows = order[bounds[k]:bounds[k + 1]]
            out.row(d, tags[int(m)], kind, len(rows), dtypes=[_INT, _INT, _INT, _SIZE_T])
            for start in range(0, len(rows), _ROWS):
                cells = ex.cells(rows[start:start + _ROWS], "gmsh") + 1
                out.table(np.column_stack([np.arange(tag, tag + len(cells)), cells]), _SIZE_T)
                tag += len(cells)
        for g in ex.groups.values():
            facets = ex.facet_nodes(g) + 1
            kind = _LINE3 if facets.shape[1] == 3 and d == 2 else GMSH_TYPE[facets.shape[1]]
            out.row(d - 1, g.id, kind, len(facets), dtypes=[_INT, _INT, _INT, _SIZE_T])
            out.table(np.column_stack([np.arange(tag, tag + len(facets)), facets]), _SIZE_T)
            tag += len(facets)
        out.end("Elements")

        # element tag -> mesh row: elements by material, then each facet's owner
        source = np.concatenate([order] + [g.owner for g in ex.groups.values()])
        data = {"material": ex.material, **ex.mesh.cell_data}
        for name, values in data.items():
            _element_data(out, name, np.asarray(values), source)


def _element_data(out: _Out, name: str, values: np.ndarray, order: np.ndarray) -> None:
    """One ``$ElementData`` section (time step 0, one component) for every element tag,
    ``values[order[tag - 1]]``."""
    m = len(order)
    out.text(f'$ElementData\n1\n"{name}"\n1\n0.0\n3\n0\n1\n{m}\n')
    record = np.dtype([("tag", _INT), ("value", np.float64)])      # packed: 12 bytes
    for start in range(0, m, _ROWS):
        rows = order[start:start + _ROWS]
        tags = np.arange(start + 1, start + len(rows) + 1)
        if out.binary:
            block = np.empty(len(rows), record)
            block["tag"], block["value"] = tags, values[rows]
            out.fh.write(block.data.cast("B"))
        elif values.dtype.kind in "biu":
            write_rows(out.fh, np.column_stack([tags, values[rows]]), encode=True)
        else:
            write_rows(out.fh, tags[:, None], values[rows][:, None], encode=True)
    out.end("ElementData")


def gmsh_materials(m, keep: list[int]):
    """Material names and (from physical tags) material ids of a Gmsh file read by meshio.

    Only physical groups of the cells' dimension name materials (those of one dimension
    less are facet groups). Returns ``(names, material)``: ``material`` is None when the
    file has no physical groups; names map material ids to group names.
    """
    if "gmsh:physical" not in m.cell_data:
        return {}, None
    dim = 3 if m.cells[keep[0]].type.startswith("tetra") else 2
    physical = np.concatenate([m.cell_data["gmsh:physical"][i] for i in keep]).astype(np.int64)
    material_of_cell = m.cell_data.get("material")
    tag_to_name = {int(tag): name for name, (tag, group_dim) in m.field_data.items()
                   if int(group_dim) == dim}
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
