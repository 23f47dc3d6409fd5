"""XDMF 3 with its arrays in an HDF5 ``.h5`` beside it (same stem), written block by block.

The layout is meshio's (``meshio.write(..., file_format="xdmf")``): one ``Grid`` with the
points as ``data0``, the cells as ``data1`` and every per-cell array after them
(``material`` first), each an HDF5 dataset (byte shuffle, then gzip: filters every HDF5
build has) named in the ``.xdmf`` as
``<stem>.h5:/dataK``, so meshio, ParaView and FEniCS read it as before. What differs is
how the arrays get there: :func:`write_xdmf_blocks` creates each dataset at its final
size and fills it :data:`BLOCK` rows at a time, converting each block (cells oriented and
given their mid-edge nodes, per-cell arrays widened to int64/float64) on its own, so no
copy of the whole mesh is made: meshio's writer needed the cells, the cell data in int64/
float64 and its own copies of them in memory at once. The HDF5 file is built in memory
(compressed, about 115 MB at 256^3) and written out in one plain write
(``_atomic.hdf5_file``): HDF5 writing onto a disk that fills up crashed the interpreter.

h5py is an optional package: without it, reading or writing ``.xdmf`` is refused with
one sentence saying what to install or choose instead. The ``.h5`` is the second target
of an ``.xdmf`` write (both land atomically together); the ``.xdmf`` names it by the
temporary's name, which is the target's (see ``io.atomic_write``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from ..._atomic import hdf5_file

__all__ = ["require_h5py", "write_xdmf_blocks", "BLOCK"]

BLOCK = 1 << 18                   # rows per block written (and per HDF5 chunk)
_GZIP = 1                         # after the byte shuffle: smaller than meshio's gzip 4
                                  # alone (115 against 122 MB at 256^3), in 60 % of the time


def require_h5py(verb: str) -> None:
    """Raise ValueError (the extra to install, what to choose) when h5py is missing."""
    from ..._extras import require

    doing = {"read": "reading", "write": "writing"}.get(verb, verb)
    require("h5py", purpose=f"{doing} .xdmf (with its .h5)", alternative="or choose .vtu")


def write_xdmf_blocks(ex, xdmf_path, h5_path) -> None:
    """Write the export mesh `ex` (``_prepare.ExportMesh``) as XDMF + HDF5, block by block.

    Parameters
    ----------
    ex : ExportMesh
        Points and cells in the files' frame, order 1 or 2.
    xdmf_path, h5_path : str or Path
        The two files (the ``.xdmf`` names the ``.h5`` by its file name).
    """
    from meshio.xdmf.common import attribute_type, meshio_to_xdmf_type, numpy_to_xdmf_dtype

    from ._common import CELL_TYPE, CELL_TYPE_2

    n = ex.n_cells
    kind = (CELL_TYPE if ex.order == 1 else CELL_TYPE_2)[ex.ndim]
    # (name, shape, dtype, block(rows) -> array); per-cell arrays widened as meshio's
    # writers need them (some reject int8 or bool)
    arrays: list[tuple[str, tuple[int, ...], np.dtype, Callable[[slice], np.ndarray]]]
    arrays = [("points", ex.points.shape, np.dtype(np.float64),
               lambda rows: ex.points[rows]),
              ("cells", (n, ex.nodes_per_cell), np.dtype(np.int64),
               lambda rows: ex.cells(rows)),
              ("material", (n,), np.dtype(np.int64), lambda rows: ex.material[rows])]
    for key, values in ex.mesh.cell_data.items():
        values = np.asarray(values)
        wide = np.dtype(np.int64 if values.dtype.kind in "biu" else np.float64)
        arrays.append((str(key), values.shape, wide, values.__getitem__))

    grid = ET.Element("Grid", Name="Grid")
    h5_name = Path(h5_path).name
    with hdf5_file(h5_path) as h5:
        for k, (name, shape, dtype, block) in enumerate(arrays):
            n_rows = max(1, shape[0])
            ds = h5.create_dataset(f"data{k}", shape=shape, dtype=dtype,
                                   chunks=(min(BLOCK, n_rows),) + tuple(shape[1:]),
                                   compression="gzip", compression_opts=_GZIP,
                                   shuffle=True)
            for start in range(0, shape[0], BLOCK):
                rows = slice(start, min(start + BLOCK, shape[0]))
                ds[rows] = np.asarray(block(rows), dtype=dtype)
            if name == "points":
                parent = ET.SubElement(grid, "Geometry", GeometryType="XYZ"[:shape[1]])
            elif name == "cells":
                parent = ET.SubElement(grid, "Topology",
                                       TopologyType=meshio_to_xdmf_type[kind][0],
                                       NumberOfElements=str(n),
                                       NodesPerElement=str(shape[1]))
            else:
                parent = ET.SubElement(grid, "Attribute", Name=name, Center="Cell",
                                       AttributeType=attribute_type(np.empty((0,) + shape[1:])))
            dt, precision = numpy_to_xdmf_dtype[dtype.name]
            item = ET.SubElement(parent, "DataItem", DataType=dt, Format="HDF",
                                 Dimensions=" ".join(map(str, shape)), Precision=precision)
            item.text = f"{h5_name}:/data{k}"
    root = ET.Element("Xdmf", Version="3.0")
    ET.SubElement(root, "Domain").append(grid)
    ET.indent(root)
    Path(xdmf_path).write_bytes(b'<?xml version="1.0"?>\n' + ET.tostring(root) + b"\n")
