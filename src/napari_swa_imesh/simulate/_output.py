"""Writing a simulation: the mesh with its fields, for ParaView and other VTK readers."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import atomic_write, check_writable
from ..mesh import to_meshio

__all__ = ["FIELD_SUFFIXES", "check_field_path", "write_field"]

FIELD_SUFFIXES = (".vtu", ".xdmf")


def check_field_path(path, *, force: bool = False) -> list[Path]:
    """The files :func:`write_field` writes for `path`, checked before any work."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in FIELD_SUFFIXES:
        raise ValueError(f"cannot write a field to {p.name!r}: use {' or '.join(FIELD_SUFFIXES)}"
                         " (VTK XML or XDMF/HDF5, both read by ParaView).")
    targets = [p] if suffix == ".vtu" else [p, p.with_suffix(".h5")]
    return [check_writable(t, force=force) for t in targets]


def field_mesh(result):
    """A ``meshio.Mesh`` of the result: point data ``potential_<axis>``, cell data
    ``material``, ``flux_<axis>`` (vectors in x, y(, z) order) and the mesh's own arrays."""
    m = to_meshio(result.mesh)
    for axis, values in result.potential.items():
        m.point_data[f"potential_{axis}"] = np.asarray(values, dtype=np.float64)
    for axis, flux in result.flux.items():
        m.cell_data[f"flux_{axis}"] = [np.asarray(flux, dtype=np.float64)]
    return m


def write_field(result, path, *, force: bool = False) -> list[Path]:
    """Write the mesh of `result` with its potentials and fluxes (``.vtu`` or ``.xdmf``).

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
    import meshio

    targets = check_field_path(path, force=force)
    m = field_mesh(result)
    with atomic_write(targets, force=force) as temps:
        if temps[0].suffix.lower() == ".vtu":
            meshio.write(temps[0], m, file_format="vtu")
        else:
            meshio.write(temps[0], m, file_format="xdmf", data_format="HDF")
    return targets
