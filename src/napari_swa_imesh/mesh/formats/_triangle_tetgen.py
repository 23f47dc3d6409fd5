"""Shewchuk-style ``.node``/``.ele`` files: Triangle in 2-D, TetGen in 3-D, with the facet
groups as Triangle ``.poly`` segments or TetGen ``.face`` faces.

meshio reads and writes TetGen files but writes them one element at a time and cannot
hold a float attribute, and it has no Triangle format, so we keep our own small writer.

Conventions (https://www.cs.cmu.edu/~quake/triangle.node.html, triangle.ele.html,
triangle.poly.html, https://wias-berlin.de/software/tetgen/fformats.node.html,
fformats.ele.html, fformats.face.html)
----------------------------------------------------------------------------------
* ``.node`` header: ``<#points> <dim> <#attributes> <#boundary markers>``, then one line
  ``<index> <x> <y> [<z>]`` per point. We write no point attributes and no markers. At
  second order the mid-edge nodes follow the corners (as ``-o2`` output does).
* ``.ele`` header, Triangle: ``<#triangles> <3 or 6> <#attributes>``; any number of float
  attributes follows the nodes. We write two: material, quality.
* ``.ele`` header, TetGen: ``<#tetrahedra> <4 or 10> <region attribute: 0 or 1>``; one
  integer region attribute at most. We write the material there (TetGen's documented use
  of it).
* Second order: the programs' ``-o2`` node order (``_order2``): Triangle's k-th extra node
  is opposite corner k; TetGen's are on edges 23 03 01 12 13 02.
* Facet groups: 2-D, a Triangle ``.poly`` whose node section is ``0 2 0 1`` (the nodes are
  those of the ``.node`` file), one segment ``<index> <a> <b> <marker>`` per facet (corners
  only: Triangle segments have two ends), and ``0`` holes; 3-D, a TetGen ``.face``
  ``<#faces> 1`` with ``<index> <a> <b> <c> [<ab> <bc> <ca>] <marker>`` per facet (the
  mid-edge nodes at second order, as TetGen's ``-o2`` writes boundary faces). The marker
  is the group id 1..K; a comment on top lists ``marker <id> <name>``. Facets are oriented
  out of their owner element (TetGen's own boundary faces point inward).
* Indices start at 1 here, like the programs' own output; the readers accept 0 or 1
  (the first point's index decides, as both programs do).
* Corners: Triangle lists them counterclockwise; for tetrahedra we keep the positive
  orientation ``det[p1-p0, p2-p0, p3-p0] > 0`` used by VTK and Gmsh (and TetGen 1.6).
* ``#`` starts a comment anywhere; we put ours on top, where meshio's TetGen reader
  also skips them.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ._text import int_rows, sci_rows

__all__ = ["write_node_ele", "write_facet_markers", "read_node_ele", "write_rows",
           "NODE_ELE_ATTRIBUTES"]

#: Names of the element attributes written, by dimension.
NODE_ELE_ATTRIBUTES = {2: ("material", "quality"), 3: ("material",)}

_PROGRAM = {2: "Triangle", 3: "TetGen"}
_FAMILY = {2: "triangle", 3: "tetgen"}
_ROWS_PER_BLOCK = 65536


def write_rows(fh, ints: np.ndarray, floats: np.ndarray | None = None, *, sep: str = " ",
               float_format: str = "%.17g", encode: bool = False) -> None:
    r"""Write text lines ``i0 i1 ... f0 f1 ...`` to `fh`, one block of rows at a time.

    Integers (and, with ``float_format="%.12e"`` after one id column, the floats) are made
    text by numpy a block at a time (:mod:`._text`: fields right-aligned and padded with
    blanks, which these formats' readers skip); the rest by one ``%`` formatting per block
    of rows, two to four times faster than ``np.savetxt``. ``%.17g`` reads back to the
    same float64. No text of the whole table is held.

    Parameters
    ----------
    fh : file
        Open for text, or for bytes with ``encode=True``.
    ints : (M, k) ndarray of int
        Exact as long as they stay below 2**53 when floats are present (they share one
        float64 block then).
    floats : (M, f) ndarray of float, optional
    sep : str
        Between the numbers of a line: one or two characters.
    float_format : str

    Examples
    --------
    >>> import io
    >>> fh = io.StringIO()
    >>> write_rows(fh, np.array([[1, 4]]), np.array([[0.5]]))
    >>> fh.getvalue()
    '1 4 0.5\n'
    >>> fh = io.StringIO()
    >>> write_rows(fh, np.array([[1, 4], [23, 5]]))
    >>> fh.getvalue()
    ' 1 4\n23 5\n'
    """
    ints = np.asarray(ints)
    k = ints.shape[1]
    f = 0 if floats is None else np.shape(floats)[1]
    line = sep.join(["%d"] * k + [float_format] * f) + "\n"
    fast_floats = f and k == 1 and float_format == "%.12e"
    fl = np.zeros((len(ints), 0)) if floats is None else floats    # read only when f
    for start in range(0, len(ints), _ROWS_PER_BLOCK):
        block = ints[start : start + _ROWS_PER_BLOCK]
        data = None
        if not f:
            data = int_rows(block, sep.encode())
        elif fast_floats:
            data = sci_rows(block, fl[start : start + _ROWS_PER_BLOCK], sep.encode())
        if data is not None:
            _write_bytes(fh, data, encode)
            continue
        if f:
            block = np.column_stack([block.astype(np.float64),
                                     fl[start : start + _ROWS_PER_BLOCK]])
        text = (line * len(block)) % tuple(block.ravel().tolist())
        fh.write(text.encode() if encode else text)


def _write_bytes(fh, data: bytes, binary: bool) -> None:
    r"""`data` (ASCII) to `fh`: as it is to a binary file, else to the bytes under a text
    file (flushed first, so the order holds; the writers open theirs with ``newline="\n"``
    so that both parts end lines alike on every platform), else decoded."""
    if binary:
        fh.write(data)
    elif hasattr(fh, "buffer"):
        fh.flush()
        fh.buffer.write(data)
    else:
        fh.write(data.decode())


def write_node_ele(ex, node_path, ele_path) -> None:
    """Write a ``.node`` and an ``.ele`` file (Triangle in 2-D, TetGen in 3-D).

    Parameters
    ----------
    ex : ExportMesh
        The mesh as files get it (``_prepare``): points, cells of order 1 or 2, material.
    node_path, ele_path : str or Path
        Files to write (replaced if they exist; the caller decides whether it may).

    Notes
    -----
    The quality is written as a second attribute in 2-D (Triangle allows several);
    TetGen allows one region attribute only, so it is dropped in 3-D.
    """
    dim = ex.ndim
    n_points, n_cells = len(ex.points), ex.n_cells
    names = list(NODE_ELE_ATTRIBUTES[dim])
    quality = ex.mesh.cell_data.get("quality") if dim == 2 else None
    if quality is None:
        names = names[:1]
    header_comment = (
        f"# {_PROGRAM[dim]} file written by napari-swa-imesh; indices start at 1\n"
    )

    with open(node_path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(header_comment)
        if ex.order == 2:
            fh.write(f"# nodes {ex.n_corners + 1}.. are edge midpoints (-o2)\n")
        fh.write(f"{n_points} {dim} 0 0\n")
        write_rows(fh, np.arange(1, n_points + 1)[:, None], ex.points)

    with open(ele_path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(header_comment)
        fh.write(f"# element attributes: {', '.join(names)}\n")
        fh.write(f"{n_cells} {ex.nodes_per_cell} {len(names)}\n")
        for start in range(0, n_cells, _ROWS_PER_BLOCK):
            rows = slice(start, start + _ROWS_PER_BLOCK)
            cells = ex.cells(rows, _FAMILY[dim]) + 1
            # integers: index, nodes, material; floats: quality (2-D)
            ints = np.column_stack([np.arange(start + 1, start + len(cells) + 1), cells,
                                    ex.material[rows]])
            floats = None if quality is None else np.asarray(quality[rows], float)[:, None]
            write_rows(fh, ints, floats)


def write_facet_markers(ex, path) -> None:
    """Write the facet groups of `ex` as a Triangle ``.poly`` (2-D) or TetGen ``.face``."""
    dim = ex.ndim
    groups = list(ex.groups.items())
    n = sum(len(g.owner) for _, g in groups)
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(f"# {_PROGRAM[dim]} file written by napari-swa-imesh: facet groups as "
                 f"boundary markers; indices start at 1\n")
        fh.write("".join(f"# marker {g.id} {name}\n" for name, g in groups))
        if dim == 2:
            fh.write("0 2 0 1\n")
        fh.write(f"{n} 1\n")
        index = 1
        for _, g in groups:
            nodes = g.facets if dim == 2 else ex.facet_nodes(g)
            ids = np.arange(index, index + len(nodes))
            write_rows(fh, np.column_stack([ids, nodes + 1, np.full(len(nodes), g.id)]))
            index += len(nodes)
        if dim == 2:
            fh.write("0\n")


def _numbers(path: Path) -> tuple[list[str], np.ndarray]:
    """Header tokens and the remaining numbers of a ``.node``/``.ele`` file."""
    text = re.sub(r"#[^\n]*", "", path.read_text())
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise ValueError(f"{path} holds no header line; is it a .node/.ele file?")
    body = " ".join(lines[1:])
    try:
        values = np.array(body.split(), dtype=np.float64)
    except ValueError as exc:
        raise ValueError(f"{path} holds a value that is not a number: {exc}") from exc
    return lines[0].split(), values


def read_node_ele(pair) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Read a Triangle or TetGen ``.node``/``.ele`` pair.

    Parameters
    ----------
    pair : (Path, Path)
        The ``.node`` and the ``.ele`` file (``_registry.node_ele_pair`` names them from
        either).

    Returns
    -------
    points : (N, d) ndarray of float64
        Coordinates as stored (x, y[, z]).
    cells : (M, d+1) ndarray of intp
        0-based corner indices (of second-order elements too: their mid-edge nodes are
        left out, and stay among the points).
    attributes : dict of str to (M,) ndarray of float64
        Element attributes, named after ``NODE_ELE_ATTRIBUTES`` when the count matches
        what we write, ``material`` for a lone (region) attribute, else
        ``attribute_1``, ``attribute_2``, ...
    """
    node_path, ele_path = (Path(q) for q in pair)
    for q in (node_path, ele_path):
        if not q.is_file():
            raise FileNotFoundError(f"no file at {q}; a .node file needs its .ele twin.")
    head, values = _numbers(node_path)
    n_points, dim, n_pattr, n_marker = (int(v) for v in (head + ["0", "0"])[:4])
    width = 1 + dim + n_pattr + n_marker
    if dim not in (2, 3) or values.size != n_points * width:
        raise ValueError(
            f"{node_path}: header says {n_points} points of dimension {dim} "
            f"({width} numbers each) but the file holds {values.size} numbers."
        )
    rows = values.reshape(n_points, width)
    base = int(rows[0, 0]) if n_points else 0
    points = rows[:, 1 : 1 + dim].copy()

    head, values = _numbers(ele_path)
    n_cells, per_cell, n_attr = (int(v) for v in (head + ["0"])[:3])
    width = 1 + per_cell + n_attr
    second = (dim + 1) * (dim + 2) // 2                    # 6 or 10 nodes (-o2)
    if per_cell not in (dim + 1, second) or values.size != n_cells * width:
        raise ValueError(
            f"{ele_path}: expected {dim + 1} (or {second}) nodes per element for {dim}-D "
            f"points and {n_cells} rows of {width} numbers; the file does not match."
        )
    rows = values.reshape(n_cells, width)
    cells = rows[:, 1 : 2 + dim].astype(np.intp) - base    # the corners come first
    ours = NODE_ELE_ATTRIBUTES[dim]
    if n_attr == len(ours):
        names = ours
    elif n_attr == 1:  # a lone attribute is a region attribute: the material
        names = ("material",)
    else:
        names = tuple(f"attribute_{k + 1}" for k in range(n_attr))
    attributes = {name: rows[:, 1 + per_cell + k].copy() for k, name in enumerate(names)}
    return points, cells, attributes
