"""Writing a simulation: the mesh with its fields, for ParaView and other VTK readers."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import hdf5_file
from .._extras import require
from ..io import atomic_write, check_writable
from ..mesh import MeshFormat, export_vectors, mesh_formats, to_meshio, write_mesh_vtu

__all__ = ["FIELD_SUFFIXES", "check_field_path", "check_series_path", "write_field",
           "write_series"]

#: the mesh formats (from the format registry) that hold fields, and the one that holds
#: a time series of them
_FIELD_FORMATS: dict[str, MeshFormat] = {f.suffix: f for f in mesh_formats() if f.fields}
(_SERIES_FORMAT,) = (f for f in mesh_formats() if f.series)
FIELD_SUFFIXES = tuple(_FIELD_FORMATS)


def _field_format(path) -> MeshFormat:
    p = Path(path)
    fmt = _FIELD_FORMATS.get(p.suffix.lower())
    if fmt is None:
        raise ValueError(f"cannot write a field to {p.name!r}: use {' or '.join(FIELD_SUFFIXES)}"
                         " (VTK XML or XDMF/HDF5, both read by ParaView).")
    return fmt


def check_field_path(path, *, force: bool = False) -> list[Path]:
    """The files :func:`write_field` writes for `path`, checked before any work."""
    p = Path(path)
    fmt = _field_format(p)
    targets = fmt.files(p)
    if fmt.requires is not None:
        plain = [f.suffix for f in _FIELD_FORMATS.values() if f.requires is None]
        require("h5py", purpose=f"writing a field as {fmt.suffix} (with its "
                f"{' and '.join(t.suffix for t in targets[1:])})",
                alternative=f"or write it as {' or '.join(plain)}")
    return [check_writable(t, force=force) for t in targets]


def _fields(result) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Point data ``potential_<axis>`` and cell data ``flux_<axis>`` (vectors in the
    file's x, y(, z): turned with the points when the mesh is placed in a world frame)."""
    mesh = result.mesh
    if isinstance(result.potential, np.ndarray):       # one field: a boundary-value run
        return ({"potential": np.asarray(result.potential, dtype=np.float64)},
                {"flux": export_vectors(mesh, np.asarray(result.flux, np.float64)[:, ::-1])})
    return ({f"potential_{axis}": np.asarray(v, dtype=np.float64)
             for axis, v in result.potential.items()},
            {f"flux_{axis}": export_vectors(mesh, np.asarray(v, dtype=np.float64)[:, ::-1])
             for axis, v in result.flux.items()})


def write_field(result, path, *, force: bool = False) -> list[Path]:
    """Write the mesh of `result` with its potentials and fluxes (``.vtu`` or ``.xdmf``):
    point data ``potential_<axis>``, cell data ``flux_<axis>`` (vectors in x, y(, z)
    order), ``material`` and the mesh's own arrays.

    Parameters
    ----------
    result : SimulationResult
    path : str or Path
        ``.vtu`` (one file) or ``.xdmf`` (with its ``.h5`` beside it).
    force : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The files written (all or none).
    """
    targets = check_field_path(path, force=force)
    write = _FIELD_WRITERS[_field_format(targets[0]).name]
    point_data, cell_data = _fields(result)
    with atomic_write(targets, force=force) as temps:
        write(result.mesh, temps, point_data, cell_data)
    return targets


def _write_vtu_fields(mesh, temps, point_data, cell_data) -> None:
    write_mesh_vtu(mesh, temps[0], point_data=point_data, cell_data=cell_data)


def _write_xdmf_fields(mesh, temps, point_data, cell_data) -> None:
    m = to_meshio(mesh)
    m.point_data.update(point_data)
    m.cell_data.update({k: [v] for k, v in cell_data.items()})
    _write_xdmf(m, temps[0], temps[1])


def _write_xdmf(m, xdmf_path, h5_path) -> None:
    """Meshio's XDMF layout (one grid; points, cells, then point and cell data as
    ``<stem>.h5:/dataK``), the HDF5 file built in memory (:func:`hdf5_file`): meshio's
    own writer lets HDF5 write to disk, which crashed on a full disk."""
    from xml.etree import ElementTree as ET

    from meshio.xdmf.common import attribute_type, meshio_to_xdmf_type, numpy_to_xdmf_dtype

    (block,) = m.cells
    grid = ET.Element("Grid", Name="Grid")
    geometry = ET.SubElement(grid, "Geometry", GeometryType="XYZ"[:m.points.shape[1]])
    topology = ET.SubElement(grid, "Topology", TopologyType=meshio_to_xdmf_type[block.type][0],
                             NumberOfElements=str(len(block.data)),
                             NodesPerElement=str(block.data.shape[1]))
    items = [(geometry, m.points), (topology, block.data)]
    for center, data in (("Node", m.point_data),
                         ("Cell", {k: v[0] for k, v in m.cell_data.items()})):
        for name, values in data.items():
            values = np.asarray(values)
            items.append((ET.SubElement(grid, "Attribute", Name=name, Center=center,
                                        AttributeType=attribute_type(values)), values))
    with hdf5_file(h5_path) as h5:
        for k, (parent, values) in enumerate(items):
            values = np.ascontiguousarray(values, dtype=np.int64 if values.dtype.kind in "biu"
                                          else np.float64)
            h5.create_dataset(f"data{k}", data=values, compression="gzip",
                              compression_opts=1, shuffle=True)
            dt, precision = numpy_to_xdmf_dtype[values.dtype.name]
            item = ET.SubElement(parent, "DataItem", DataType=dt, Format="HDF",
                                 Dimensions=" ".join(map(str, values.shape)),
                                 Precision=precision)
            item.text = f"{Path(h5_path).name}:/data{k}"
    root = ET.Element("Xdmf", Version="3.0")
    ET.SubElement(root, "Domain").append(grid)
    ET.indent(root)
    Path(xdmf_path).write_bytes(b'<?xml version="1.0"?>\n' + ET.tostring(root) + b"\n")


#: how each field format (by its registry name) is written
_FIELD_WRITERS = {"vtu": _write_vtu_fields, "xdmf": _write_xdmf_fields}


def check_series_path(path, *, force: bool = False) -> list[Path]:
    """The files :func:`write_series` writes (``.xdmf`` and its ``.h5``), checked."""
    p = Path(path)
    fmt = _SERIES_FORMAT
    if p.suffix.lower() not in fmt.suffixes:
        raise ValueError(f"a time series is written as XDMF/HDF5: name the output "
                         f"{p.with_suffix(fmt.suffix).name!r} instead of {p.name!r}.")
    targets = fmt.files(p)
    require("h5py", purpose=f"writing a time series ({fmt.suffix} with its "
            f"{' and '.join(t.suffix for t in targets[1:])})")
    return [check_writable(t, force=force) for t in targets]


def write_series(result, path, *, force: bool = False, name: str = "u") -> list[Path]:
    """Write a :class:`TransientResult` as one XDMF time series (ParaView reads it).

    One HDF5 file beside the ``.xdmf`` holds the mesh once (x, y(, z) order, ``material``
    per cell) and field `name` at the vertices for every saved time; the XDMF names it by
    its file name only, so the pair can be moved together. (meshio's own time-series
    writer puts the ``.h5`` in the working directory, not beside the ``.xdmf``.) The
    error estimate per saved time goes in ``error/space`` and ``error/time`` (absolute,
    NaN where not estimated) beside ``error/jump``, the scale it is relative to.
    """
    targets = check_series_path(path, force=force)
    m = to_meshio(result.mesh)
    points, cells = m.points, m.cells[0].data
    material = m.cell_data["material"][0]
    h5_name = targets[1].name
    topology = "Triangle" if cells.shape[1] == 3 else "Tetrahedron"
    geometry = "XY" if points.shape[1] == 2 else "XYZ"

    def item(dataset: str, array: np.ndarray) -> str:
        kind = "Int" if array.dtype.kind in "iu" else "Float"
        dims = " ".join(map(str, array.shape))
        return (f'<DataItem Dimensions="{dims}" NumberType="{kind}" Precision="8" '
                f'Format="HDF">{h5_name}:/{dataset}</DataItem>')

    grids = []
    with atomic_write(targets, force=force) as (xdmf_tmp, h5_tmp):
        with hdf5_file(h5_tmp) as h5:
            h5["points"] = points
            h5["cells"] = cells.astype(np.int64)
            h5["material"] = material.astype(np.int64)
            estimate = getattr(result, "error", None)
            if estimate is not None:       # per saved time; NaN where not estimated
                h5["error/space"] = np.asarray(estimate.space, dtype=np.float64)
                h5["error/time"] = np.asarray(estimate.time, dtype=np.float64)
                h5["error/jump"] = float(estimate.jump)
            for k, (time, values) in enumerate(zip(result.times, result.values)):
                h5[f"{name}/{k}"] = np.asarray(values, dtype=np.float64)
                grids.append(
                    f'<Grid Name="step{k}" GridType="Uniform"><Time Value="{float(time)!r}"/>'
                    f'<Topology TopologyType="{topology}" NumberOfElements="{len(cells)}">'
                    f'{item("cells", cells.astype(np.int64))}</Topology>'
                    f'<Geometry GeometryType="{geometry}">{item("points", points)}</Geometry>'
                    f'<Attribute Name="material" AttributeType="Scalar" Center="Cell">'
                    f'{item("material", material.astype(np.int64))}</Attribute>'
                    f'<Attribute Name="{name}" AttributeType="Scalar" Center="Node">'
                    f'{item(f"{name}/{k}", np.asarray(values, dtype=np.float64))}</Attribute>'
                    f'</Grid>')
        xdmf_tmp.write_text(
            '<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain>'
            '<Grid Name="series" GridType="Collection" CollectionType="Temporal">\n'
            + "\n".join(grids) + "\n</Grid></Domain></Xdmf>\n")
    return targets
