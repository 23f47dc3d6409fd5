"""VTK XML unstructured grid (``.vtu``) with appended base64 data, streamed array by array.

One XML header that lists every array with its offset, then the arrays after
``<AppendedData encoding="base64">_``, each as its length in bytes (UInt64,
``header_type="UInt64"``, encoded on its own, as VTK's own writer does) followed by its
bytes. The bytes are encoded in slices of a multiple of 3 bytes, so the slices' base64
texts join into the base64 of the whole array: writing needs no copy of the mesh and no
memory beyond one slice. (Raw appended data would be smaller still, but meshio, which many
FE tool chains read meshes with, reads only base64.) VTK (ParaView, pyvista) and meshio
read it.
"""

from __future__ import annotations

import base64
import sys
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

__all__ = ["write_vtu"]

#: VTK cell type id by nodes per cell: VTK_TRIANGLE, VTK_TETRA, VTK_QUADRATIC_TRIANGLE,
#: VTK_QUADRATIC_TETRA (lines, VTK_LINE 3 and VTK_QUADRATIC_EDGE 21, are asked by name).
VTK_CELL_TYPE = {3: 5, 4: 10, 6: 22, 10: 24}
_VTK_TYPE = {"i1": "Int8", "u1": "UInt8", "i2": "Int16", "u2": "UInt16", "i4": "Int32",
             "u4": "UInt32", "i8": "Int64", "u8": "UInt64", "f4": "Float32", "f8": "Float64"}
_ORDER = "LittleEndian" if sys.byteorder == "little" else "BigEndian"
_SLICE = 3 << 20                 # bytes per base64 slice: a multiple of 3, a few MB


def _b64_length(n_bytes: int) -> int:
    return 4 * ((n_bytes + 2) // 3)


def _write_b64(fh, values: np.ndarray) -> None:
    """The base64 of `values`' bytes, slice by slice (no copy of the whole array)."""
    raw = memoryview(values.reshape(-1)).cast("B")
    for start in range(0, len(raw), _SLICE):
        fh.write(base64.b64encode(raw[start:start + _SLICE]))


def _vtk_array(values: np.ndarray) -> np.ndarray:
    """`values` in a dtype VTK names (bool as UInt8), native byte order; a view if it is."""
    values = np.asarray(values)
    if values.dtype == bool:
        return values.view(np.uint8)
    dtype = values.dtype.newbyteorder("=")
    if f"{dtype.kind}{dtype.itemsize}" not in _VTK_TYPE:
        dtype = np.dtype(np.int64 if dtype.kind in "iu" else np.float64)
    return np.ascontiguousarray(values, dtype=dtype)


def _type_name(values: np.ndarray) -> str:
    return _VTK_TYPE[f"{values.dtype.kind}{values.dtype.itemsize}"]


def _field_data(arrays: dict) -> str:
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
              field_data: dict[str, np.ndarray] | None = None,
              cell_type: int | None = None) -> None:
    """Write a mesh of one cell type (triangles or tetrahedra by default) as a ``.vtu`` file.

    Parameters
    ----------
    path : str or Path
    points : (N, 2) or (N, 3) array_like of float
        In the file's x, y(, z) order; 2-D points get z = 0.
    cells : (M, 3) or (M, 4) array_like of int
        Triangles or tetrahedra, oriented as the file should have them.
    cell_data, point_data : dict of str to (M,) / (N,) or (M, k) / (N, k) array_like
        Arrays per cell and per point (k components).
    field_data : dict of str to (n,) array_like of int, optional
        Small integer arrays of the whole grid (``<FieldData>``, written as text; VTK
        and meshio read them).
    cell_type : int, optional
        VTK cell type id; by default from the nodes per cell (:data:`VTK_CELL_TYPE`).
    """
    points = np.asarray(points, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    cells = np.asarray(cells)
    n_cells, corners = cells.shape
    arrays: list[tuple[str, str, np.ndarray]] = [
        ("Points", "", _vtk_array(points)),
        ("Cells", "connectivity", _vtk_array(cells.astype(np.int64, copy=False).ravel())),
        ("Cells", "offsets", np.arange(corners, corners * n_cells + 1, corners,
                                       dtype=np.int64)),
        ("Cells", "types", np.full(n_cells, cell_type or VTK_CELL_TYPE[corners],
                                   dtype=np.uint8)),
    ]
    for section, data in (("CellData", cell_data or {}), ("PointData", point_data or {})):
        arrays += [(section, str(name), _vtk_array(values)) for name, values in data.items()]

    offset = 0
    tags: dict[str, list[str]] = {"Points": [], "Cells": [], "CellData": [], "PointData": []}
    for section, name, values in arrays:
        named = f' Name="{name}"' if name else ""
        # one-component arrays say nothing (meshio reads an explicit 1 as (n, 1))
        components = "" if values.ndim == 1 else f' NumberOfComponents="{values.shape[1]}"'
        tags[section].append(
            f'<DataArray type="{_type_name(values)}"{named}{components} '
            f'format="appended" offset="{offset}"/>')
        offset += _b64_length(8) + _b64_length(values.nbytes)
    body = "".join(f"<{s}>{''.join(t)}</{s}>" for s, t in tags.items() if t)
    header = (f'<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" '
              f'byte_order="{_ORDER}" header_type="UInt64"><UnstructuredGrid>'
              f'{_field_data(field_data or {})}<Piece NumberOfPoints="{len(points)}" NumberOfCells="{n_cells}">{body}'
              f'</Piece></UnstructuredGrid><AppendedData encoding="base64">_')
    with open(Path(path), "wb") as fh:
        fh.write(header.encode("ascii"))
        for _, _, values in arrays:
            fh.write(base64.b64encode(np.uint64(values.nbytes).tobytes()))
            _write_b64(fh, values)
        fh.write(b"</AppendedData></VTKFile>\n")
