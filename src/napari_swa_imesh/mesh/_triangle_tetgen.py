"""Shewchuk-style ``.node``/``.ele`` files: Triangle in 2-D, TetGen in 3-D.

meshio reads and writes TetGen files but writes them one element at a time and cannot
hold a float attribute, and it has no Triangle format, so we keep our own small writer.

Conventions (https://www.cs.cmu.edu/~quake/triangle.node.html, triangle.ele.html,
https://wias-berlin.de/software/tetgen/fformats.node.html, fformats.ele.html)
----------------------------------------------------------------------------------
* ``.node`` header: ``<#points> <dim> <#attributes> <#boundary markers>``, then one line
  ``<index> <x> <y> [<z>]`` per point. We write no point attributes and no markers.
* ``.ele`` header, Triangle: ``<#triangles> 3 <#attributes>``; any number of float
  attributes follows the corners. We write two: material, quality.
* ``.ele`` header, TetGen: ``<#tetrahedra> 4 <region attribute: 0 or 1>``; one integer
  region attribute at most. We write the material there (TetGen's documented use of it).
* Indices start at 1 here, like the programs' own output; the readers accept 0 or 1
  (the first point's index decides, as both programs do).
* Corners: Triangle lists them counterclockwise; for tetrahedra we keep the positive
  orientation ``det[p1-p0, p2-p0, p3-p0] > 0`` used by VTK and Gmsh.
* ``#`` starts a comment anywhere; we put ours on top, where meshio's TetGen reader
  also skips them.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

__all__ = ["write_node_ele", "read_node_ele", "format_rows", "NODE_ELE_ATTRIBUTES"]

#: Names of the element attributes written, by dimension.
NODE_ELE_ATTRIBUTES = {2: ("material", "quality"), 3: ("material",)}

_PROGRAM = {2: "Triangle", 3: "TetGen"}
_ROWS_PER_BLOCK = 65536


def format_rows(ints: np.ndarray, floats: np.ndarray | None = None) -> str:
    r"""Text lines ``i0 i1 ... f0 f1 ...``: integers as such, floats with 17 digits.

    One ``%`` formatting per block of rows instead of one per row (``np.savetxt``): two
    to four times faster. ``%.17g`` reads back to the same float64.

    Parameters
    ----------
    ints : (M, k) ndarray of int
        Exact as long as they stay below 2**53 when floats are present (they share one
        float64 block then).
    floats : (M, f) ndarray of float, optional

    Examples
    --------
    >>> format_rows(np.array([[1, 4]]), np.array([[0.5]]))
    '1 4 0.5\n'
    """
    ints = np.asarray(ints, dtype=np.int64)
    k = ints.shape[1]
    if floats is None or np.shape(floats)[1] == 0:
        table, line = ints, " ".join(["%d"] * k) + "\n"
    else:
        floats = np.asarray(floats, dtype=np.float64)
        table = np.column_stack([ints.astype(np.float64), floats])
        line = " ".join(["%d"] * k + ["%.17g"] * floats.shape[1]) + "\n"
    parts = []
    for start in range(0, len(table), _ROWS_PER_BLOCK):
        block = table[start : start + _ROWS_PER_BLOCK]
        parts.append((line * len(block)) % tuple(block.ravel().tolist()))
    return "".join(parts)


def write_node_ele(
    node_path,
    ele_path,
    points: np.ndarray,
    cells: np.ndarray,
    material: np.ndarray,
    quality: np.ndarray | None = None,
) -> None:
    """Write a ``.node`` and an ``.ele`` file (Triangle in 2-D, TetGen in 3-D).

    Parameters
    ----------
    node_path, ele_path : str or Path
        Files to write (replaced if they exist; the caller decides whether it may).
    points : (N, d) ndarray of float
        Coordinates in the file's axis order (x, y[, z]); d is 2 or 3.
    cells : (M, d+1) ndarray of int
        0-based corner indices, positively oriented in those coordinates.
    material : (M,) ndarray of int
        Material id of each element (the region attribute).
    quality : (M,) ndarray of float, optional
        Written as a second attribute in 2-D (Triangle allows several); TetGen allows
        one region attribute only, so it is dropped in 3-D.
    """
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells)
    dim = points.shape[1]
    n_points, n_cells = points.shape[0], cells.shape[0]
    attrs = [np.asarray(material, dtype=np.int64)]
    names = ["material"]
    if dim == 2 and quality is not None:
        attrs.append(np.asarray(quality, dtype=np.float64))
        names.append("quality")
    header_comment = (
        f"# {_PROGRAM[dim]} file written by napari-swa-imesh; indices start at 1\n"
    )

    with open(node_path, "w") as fh:
        fh.write(header_comment)
        fh.write(f"{n_points} {dim} 0 0\n")
        fh.write(format_rows(np.arange(1, n_points + 1)[:, None], points))

    # integers (M, 1+(d+1)+1): index, corners, material; floats (M, 0 or 1): quality
    ele_ints = np.column_stack([np.arange(1, n_cells + 1), cells + 1, attrs[0]])
    ele_floats = np.column_stack(attrs[1:]) if len(attrs) > 1 else None
    with open(ele_path, "w") as fh:
        fh.write(header_comment)
        fh.write(f"# element attributes: {', '.join(names)}\n")
        fh.write(f"{n_cells} {dim + 1} {len(attrs)}\n")
        fh.write(format_rows(ele_ints, ele_floats))


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


def read_node_ele(path) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Read a Triangle or TetGen ``.node``/``.ele`` pair (either name may be given).

    Returns
    -------
    points : (N, d) ndarray of float64
        Coordinates as stored (x, y[, z]).
    cells : (M, d+1) ndarray of intp
        0-based corner indices.
    attributes : dict of str to (M,) ndarray of float64
        Element attributes, named after ``NODE_ELE_ATTRIBUTES`` when the count matches
        what we write, ``material`` for a lone (region) attribute, else
        ``attribute_1``, ``attribute_2``, ...
    """
    p = Path(path)
    node_path, ele_path = p.with_suffix(".node"), p.with_suffix(".ele")
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
    if per_cell != dim + 1 or values.size != n_cells * width:
        raise ValueError(
            f"{ele_path}: expected {dim + 1} corners per element for {dim}-D points and "
            f"{n_cells} rows of {width} numbers; the file does not match."
        )
    rows = values.reshape(n_cells, width)
    cells = rows[:, 1 : 1 + per_cell].astype(np.intp) - base
    ours = NODE_ELE_ATTRIBUTES[dim]
    if n_attr == len(ours):
        names = ours
    elif n_attr == 1:  # a lone attribute is a region attribute: the material
        names = ("material",)
    else:
        names = [f"attribute_{k + 1}" for k in range(n_attr)]
    attributes = {name: rows[:, 1 + per_cell + k].copy() for k, name in enumerate(names)}
    return points, cells, attributes
