"""VTK XML unstructured grid (``.vtu``) with raw appended data, streamed array by array.

One XML header that lists every array with its offset, then the arrays after
``<AppendedData encoding="raw">_``, each as its length in bytes (UInt64,
``header_type="UInt64"``) followed by its bytes, and a line break before the closing tag
(meshio's reader of raw data cuts the data at the last one). Raw bytes go from numpy
straight to the file: no encoding pass, a quarter fewer bytes than base64, no copy of
the mesh (connectivity, offsets and cell types are written in chunks). Connectivity and
offsets are Int32 when the ids fit, and so is any 64-bit integer array whose values all
fit (labels, leaf ids: readers get the same values in 4 bytes instead of 8; a label of
2**31 or more keeps the array Int64). Floats keep their width: float32 would round the
worst quality sqrt(5)/2 up, past its bound. VTK (ParaView, pyvista) and meshio read it.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import ArrayLike

from ..model._quality import _corner_det

__all__ = ["CellBlocks", "write_vtu"]

#: VTK cell type id by nodes per cell: VTK_TRIANGLE, VTK_TETRA, VTK_QUADRATIC_TRIANGLE,
#: VTK_QUADRATIC_TETRA (lines, VTK_LINE 3 and VTK_QUADRATIC_EDGE 21, are asked by name).
VTK_CELL_TYPE = {3: 5, 4: 10, 6: 22, 10: 24}
_VTK_TYPE = {"i1": "Int8", "u1": "UInt8", "i2": "Int16", "u2": "UInt16", "i4": "Int32",
             "u4": "UInt32", "i8": "Int64", "u8": "UInt64", "f4": "Float32", "f8": "Float64"}
_ORDER = "LittleEndian" if sys.byteorder == "little" else "BigEndian"
_CHUNK = 1 << 16                 # cells per chunk of connectivity (in cache)


def _vtk_array(values: np.ndarray) -> np.ndarray:
    """`values` in a dtype VTK names (bool as UInt8), native byte order; a view if it is."""
    values = np.asarray(values)
    if values.dtype == bool:
        return values.view(np.uint8)
    dtype = values.dtype.newbyteorder("=")
    if f"{dtype.kind}{dtype.itemsize}" not in _VTK_TYPE:
        dtype = np.dtype(np.int64 if dtype.kind in "iu" else np.float64)
    return np.ascontiguousarray(values, dtype=dtype)


def _narrowed(values: np.ndarray):
    """`values` (a :func:`_vtk_array`) as Int32 when 64-bit integers that all fit: one
    array, converted chunk by chunk as it is written (no copy of the whole); else as is."""
    if values.dtype.itemsize != 8 or values.dtype.kind not in "iu" or not values.size:
        return values
    if int(values.min()) < -2**31 or int(values.max()) >= 2**31:
        return values
    if values.ndim != 1:
        return values.astype(np.int32)
    return _Chunked(np.int32, len(values), lambda: (
        values[start:start + _CHUNK].astype(np.int32)
        for start in range(0, len(values), _CHUNK)))


def _type_name(dtype: np.dtype) -> str:
    return _VTK_TYPE[f"{dtype.kind}{dtype.itemsize}"]


class CellBlocks:
    """Cells handed over block by block (so the writer never holds them all): `n` rows of
    `width` ids, ``block(start, stop)`` returns rows ``start:stop``."""

    def __init__(self, n: int, width: int, block):
        self.n, self.width, self.block = n, width, block


class _Chunked:
    """An array written chunk by chunk: dtype, shape and a function yielding the chunks."""

    def __init__(self, dtype, n: int, chunks):
        self.dtype, self.shape, self.ndim, self.chunks = np.dtype(dtype), (n,), 1, chunks
        self.nbytes = n * self.dtype.itemsize


def _connectivity(points: np.ndarray, cells: np.ndarray, dtype, orient: bool):
    """Chunks of the cell ids; with `orient`, corners 0 and 1 swapped where the volume is
    negative, so every cell is positively oriented in the file."""
    coords = [np.ascontiguousarray(points[:, a]) for a in range(points.shape[1])] if orient else []
    blocks = cells if isinstance(cells, CellBlocks) else None
    for start in range(0, blocks.n if blocks else len(cells), _CHUNK):
        chunk = (blocks.block(start, start + _CHUNK) if blocks
                 else cells[start:start + _CHUNK]).astype(dtype)
        if orient:
            det = _corner_det([[x[chunk[:, k]] for x in coords] for k in range(chunk.shape[1])])
            flip = det < 0
            chunk[flip, 0], chunk[flip, 1] = chunk[flip, 1], chunk[flip, 0].copy()
        yield chunk


def _field_data(arrays: Mapping) -> str:
    """``<FieldData>`` of small integer arrays, inline as text (names escaped)."""
    if not arrays:
        return ""
    tags = "".join(
        f'<DataArray type="Int64" Name={quoteattr(str(name))} '
        f'NumberOfTuples="{np.size(v)}" format="ascii">'
        f'{" ".join(str(int(x)) for x in np.ravel(v))}</DataArray>'
        for name, v in arrays.items())
    return f"<FieldData>{tags}</FieldData>"


def write_vtu(path, points: np.ndarray, cells: np.ndarray, *,
              cell_data: dict[str, np.ndarray] | None = None,
              point_data: dict[str, np.ndarray] | None = None,
              field_data: Mapping[str, ArrayLike] | None = None,
              cell_type: int | None = None, orient: bool = False) -> None:
    """Write a mesh of one cell type (triangles or tetrahedra by default) as a ``.vtu`` file.

    Parameters
    ----------
    path : str or Path
    points : (N, 2) or (N, 3) array_like of float
        In the file's x, y(, z) order; 2-D points get z = 0.
    cells : (M, k) array_like of int, or CellBlocks
        Triangles or tetrahedra (any cell of `cell_type`), or the same handed over
        block by block.
    cell_data, point_data : dict of str to (M,) / (N,) or (M, k) / (N, k) array_like
        Arrays per cell and per point (k components), in their dtypes, except that 64-bit
        integers whose values all fit in Int32 are written as Int32 (same values).
    field_data : dict of str to (n,) array_like of int, optional
        Small integer arrays of the whole grid (``<FieldData>``, written as text; VTK
        and meshio read them).
    cell_type : int, optional
        VTK cell type id; by default from the nodes per cell (:data:`VTK_CELL_TYPE`).
    orient : bool
        Swap two corners of each cell with a negative volume in `points` (chunk by chunk,
        without a copy of `cells`; linear simplices only); otherwise cells are written as
        given.
    """
    points = np.asarray(points, dtype=np.float64)
    if isinstance(cells, CellBlocks):
        if orient:
            raise ValueError("orient needs the cells as an array, not as CellBlocks.")
        n_cells, corners = cells.n, cells.width
    else:
        cells = np.asarray(cells)
        n_cells, corners = cells.shape
    n_points = len(points)
    id_type = np.int32 if max(n_points, corners * n_cells) < 2**31 else np.int64

    def offsets():
        for start in range(0, n_cells, _CHUNK):
            stop = min(start + _CHUNK, n_cells)
            yield np.arange(corners * (start + 1), corners * stop + 1, corners, dtype=id_type)

    def types():
        for start in range(0, n_cells, _CHUNK):
            yield np.full(min(_CHUNK, n_cells - start), cell_type or VTK_CELL_TYPE[corners],
                          dtype=np.uint8)

    arrays: list[tuple[str, str, np.ndarray | _Chunked]] = [
        ("Points", "", _vtk_array(np.column_stack([points, np.zeros(n_points)])
                                  if points.shape[1] == 2 else points)),
        ("Cells", "connectivity", _Chunked(id_type, n_cells * corners,
                                           lambda: _connectivity(points, cells, id_type,
                                                                 orient))),
        ("Cells", "offsets", _Chunked(id_type, n_cells, offsets)),
        ("Cells", "types", _Chunked(np.uint8, n_cells, types)),
    ]
    for section, data in (("CellData", cell_data or {}), ("PointData", point_data or {})):
        arrays += [(section, str(name), _narrowed(_vtk_array(values)))
                   for name, values in data.items()]

    # the data go in the reverse of the tags' order: meshio turns raw data into base64
    # block by block, looking each tag up by its old offset in document order after
    # rewriting the offsets of the blocks before it, and a rewritten offset can equal a
    # later block's old one; reversed, every block already rewritten comes after the one
    # looked up, so the lookup finds the right tag (VTK reads by offset, in any order)
    offsets_of = {}
    offset = 0
    for index in reversed(range(len(arrays))):
        offsets_of[index] = offset
        offset += 8 + arrays[index][2].nbytes
    tags: dict[str, list[str]] = {"Points": [], "Cells": [], "CellData": [], "PointData": []}
    for index, (section, name, values) in enumerate(arrays):
        named = f' Name="{name}"' if name else ""
        # one-component arrays say nothing (meshio reads an explicit 1 as (n, 1))
        components = "" if values.ndim == 1 else f' NumberOfComponents="{values.shape[1]}"'
        tags[section].append(
            f'<DataArray type="{_type_name(values.dtype)}"{named}{components} '
            f'format="appended" offset="{offsets_of[index]}"/>')
    body = "".join(f"<{s}>{''.join(t)}</{s}>" for s, t in tags.items() if t)
    header = (f'<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" '
              f'byte_order="{_ORDER}" header_type="UInt64"><UnstructuredGrid>'
              f'{_field_data(field_data or {})}'
              f'<Piece NumberOfPoints="{n_points}" NumberOfCells="{n_cells}">{body}'
              f'</Piece></UnstructuredGrid><AppendedData encoding="raw">_')
    with open(Path(path), "wb") as fh:
        fh.write(header.encode("ascii"))
        for _, _, values in reversed(arrays):
            fh.write(np.uint64(values.nbytes).tobytes())
            for chunk in (values.chunks() if isinstance(values, _Chunked) else (values,)):
                fh.write(memoryview(chunk.reshape(-1)).cast("B"))
        fh.write(b"\n</AppendedData></VTKFile>\n")
