"""Writing and reading meshes in the formats finite-element users expect: the dispatcher.

This module picks a writer by suffix and sends every write through ``io.atomic_write``;
each awkward format keeps its workarounds in a module of its own (``_gmsh``, ``_abaqus``,
``_xdmf``, ``_triangle_tetgen``), the rest is a plain meshio call. Exported coordinates
are x, y(, z) = column, row(, plane), the reverse of the numpy axis order the ``Mesh``
keeps; each cell is reordered so that its signed volume stays positive there.

What each format holds
----------------------
========  ==========================================================================
``.vtu``  VTK XML (raw binary, streamed); points padded to z = 0 in 2-D; every per-cell array.
``.vtk``  legacy VTK 4.2 (readable by any VTK); points padded; every per-cell array.
``.msh``  Gmsh 4.1 ASCII; one physical group (and one entity) per material, named
          after it; every per-cell array as ``$ElementData``.
``.xdmf`` XDMF 3 with its arrays in a ``.h5`` beside it (same stem; needs h5py); every
          array.
``.inp``  Abaqus; one ``*ELSET`` per material named after it (made a valid Abaqus
          label: ``soft tissue`` -> ``soft_tissue``); CPS3 triangles in 2-D, C3D4
          tetrahedra in 3-D; no per-cell arrays (the format has none).
``.node`` Triangle (2-D; attributes material, quality) or TetGen (3-D; region
``.ele``  attribute material); both files are written, with the same stem.
========  ==========================================================================
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import atomic_write, check_writable
from ._abaqus import ABAQUS_ELEMENTS, abaqus_materials, write_abaqus
from ._common import CELL_TYPE, export_points
from ._common import orient_positive as _orient_positive  # shared with the pyvista bridge
from ._facets import facet_groups
from ._gmsh import gmsh_materials, write_gmsh
from ._triangle_tetgen import read_node_ele, write_node_ele
from ._types import Mesh
from ._vtu import write_vtu
from ._xdmf import require_h5py, write_xdmf

__all__ = ["to_meshio", "write_mesh", "write_mesh_vtu", "read_mesh", "mesh_output_paths",
           "MESH_SUFFIXES"]

#: Suffix -> short description, in the order shown to users.
MESH_SUFFIXES = {
    ".vtu": "VTK XML unstructured grid",
    ".vtk": "legacy VTK",
    ".msh": "Gmsh 4.1 with physical groups",
    ".xdmf": "XDMF with its HDF5 .h5 file",
    ".inp": "Abaqus with one element set per material",
    ".node": "Triangle (2-D) / TetGen (3-D) .node + .ele",
    ".ele": "Triangle (2-D) / TetGen (3-D) .node + .ele",
}


# ----------------------------------------------------------------------------- helpers


def _check_mesh_arg(mesh) -> None:
    """A `Mesh` (which checked its own arrays when built) with something to write."""
    if not isinstance(mesh, Mesh):
        raise TypeError(
            f"expected a napari_swa_imesh Mesh (from mesh_labels or read_mesh); got "
            f"{type(mesh).__name__}."
        )
    if mesh.n_cells == 0:
        raise ValueError("the mesh has no elements; there is nothing to write.")


# ----------------------------------------------------------------------------- to meshio


def to_meshio(mesh: Mesh):
    """Convert a `Mesh` to a ``meshio.Mesh`` in x, y(, z) order.

    Parameters
    ----------
    mesh : Mesh
        Points (N, d) in (plane, row, col) order, cells (M, d+1), ``material`` (M,).

    Returns
    -------
    meshio.Mesh
        ``points`` (N, d) float64 as (col, row[, plane]); one cell block of type
        ``triangle`` or ``tetra`` with positive signed volume in those coordinates;
        ``cell_data`` ``material`` (int64), ``quality`` and every other per-cell array of
        the mesh (integers as int64, the rest as float64), each as a one-element list
        (one block).

    Examples
    --------
    >>> import numpy as np
    >>> m = Mesh(np.array([[0., 0.], [0., 1.], [1., 0.]]), np.array([[0, 2, 1]]),
    ...          np.array([1]), {"quality": np.array([0.707])})
    >>> to_meshio(m).points.tolist()
    [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    """
    import meshio

    _check_mesh_arg(mesh)
    points = export_points(mesh)
    cells = _orient_positive(points, mesh.cells)
    cell_data = {"material": [np.asarray(mesh.material, dtype=np.int64)]}
    for key, values in mesh.cell_data.items():
        values = np.asarray(values)
        # every writer takes int64/float64; some reject int8 or bool (XDMF as XML)
        kind = values.dtype.kind
        cell_data[key] = [values.astype(np.int64 if kind in "biu" else np.float64)]
    return meshio.Mesh(points, [(CELL_TYPE[mesh.ndim], cells)], cell_data=cell_data)


def _padded(m):
    """The same meshio mesh with 2-D points given z = 0 (VTK formats need 3-D points)."""
    import meshio

    if m.points.shape[1] == 3:
        return m
    points = np.column_stack([m.points, np.zeros(len(m.points))])
    return meshio.Mesh(points, m.cells, cell_data=m.cell_data)


# ----------------------------------------------------------------------------- writing


def _targets(path: Path) -> list[Path]:
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        listed = ", ".join(MESH_SUFFIXES)
        raise ValueError(
            f"cannot write a mesh as {path.name!r}: unknown suffix {suffix or '(none)'!r}; "
            f"use one of {listed}."
        )
    if suffix in (".node", ".ele"):
        return [path.with_suffix(".node"), path.with_suffix(".ele")]
    if suffix == ".xdmf":
        return [path, path.with_suffix(".h5")]
    return [path]


def mesh_output_paths(path, *, force: bool = False) -> list[Path]:
    """The files `write_mesh` would write for `path`, after checking it may write them.

    Lets a caller fail fast (before meshing) on a bad suffix or an existing file.

    Parameters
    ----------
    path : str or Path
        As for :func:`write_mesh`.
    force : bool
        Whether existing files may be replaced.

    Returns
    -------
    list of Path
        One path, or two (``.node`` and ``.ele``; ``.xdmf`` and its ``.h5``).

    Raises
    ------
    ValueError
        Unknown suffix (the message lists the supported ones).
    FileExistsError
        A target exists and `force` is false.
    FileNotFoundError
        The target folder does not exist.
    """
    targets = _targets(Path(path))
    for target in targets:
        check_writable(target, force=force)
    return targets


def write_mesh(mesh: Mesh, path, *, force: bool = False,
               abaqus_elements: str = "mechanical") -> list[Path]:
    """Write `mesh` in the format named by the suffix of `path`.

    Parameters
    ----------
    mesh : Mesh
        A triangle (2-D) or tetrahedron (3-D) mesh with ``material`` per element.
    path : str or Path
        ``.vtu``, ``.vtk``, ``.msh`` (Gmsh 4.1), ``.xdmf``, ``.inp`` (Abaqus), or
        ``.node``/``.ele`` (Triangle in 2-D, TetGen in 3-D: both files are written).
    force : bool
        Replace existing files. Without it, any existing target is an error and nothing
        is written.
    abaqus_elements : {"mechanical", "heat"}
        Element types of an ``.inp``: continuum (``CPS3``/``C3D4``) or heat transfer
        (``DC2D3``/``DC3D4``, for ``*HEAT TRANSFER``).

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        Unknown suffix, or a mesh that cannot be written.
    FileExistsError
        A target exists and `force` is false (all targets are checked first).

    Notes
    -----
    Every file is written under a temporary name in the target folder and then moved
    into place, so a failed write never leaves a half file where the user's was.
    """
    _check_mesh_arg(mesh)
    if abaqus_elements not in ABAQUS_ELEMENTS:
        raise ValueError(f"abaqus_elements must be one of {', '.join(ABAQUS_ELEMENTS)}, not "
                         f"{abaqus_elements!r}.")
    targets = mesh_output_paths(path, force=force)
    with atomic_write(targets, force=force) as temps:
        write_mesh_to(mesh, temps, abaqus_elements=abaqus_elements)
    return targets


def write_mesh_to(mesh: Mesh, temps: list[Path], *, abaqus_elements: str = "mechanical"
                  ) -> None:
    """Write `mesh` to the temporary paths that :func:`atomic_write` gave for the targets
    of :func:`mesh_output_paths` (same names, so twins name each other right)."""
    import meshio

    suffix = temps[0].suffix.lower()
    if suffix == ".vtu":                      # our own writer: no meshio copy of the mesh
        write_mesh_vtu(mesh, temps[0])
        return
    m = to_meshio(mesh)
    try:
        if suffix == ".inp":
            write_abaqus(mesh.material_names, m, str(temps[0]), groups=facet_groups(mesh),
                         cells_mesh=mesh.cells, elements=abaqus_elements)
            return
        _WRITERS[suffix](mesh, m, [str(t) for t in temps])
    except (meshio.WriteError, KeyError) as exc:  # meshio's own failures, as one clear line
        raise ValueError(f"meshio could not write {temps[0].name}: {exc}") from exc


def write_mesh_vtu(mesh: Mesh, path, *, point_data: dict | None = None,
                   cell_data: dict | None = None) -> None:
    """Write `mesh` to `path` as ``.vtu`` with extra per-point and per-cell arrays.

    The writer behind :func:`write_mesh`'s ``.vtu`` (x, y(, z) order, cells positive
    there, ``material`` and the mesh's own arrays in their dtypes; see :mod:`._vtu`), for
    callers that add fields and write through :func:`~napari_swa_imesh.io.atomic_write`
    themselves. Vectors in `cell_data`/`point_data` must already be in x, y(, z) order.
    """
    points = export_points(mesh)
    data = {"material": mesh.material, **mesh.cell_data, **(cell_data or {})}
    write_vtu(path, points, mesh.cells, cell_data=data, point_data=point_data, orient=True)


def _write_vtk(mesh: Mesh, m, temps: list[str]) -> None:
    import meshio

    meshio.write(temps[0], _padded(m), file_format="vtk42", binary=True)


def _write_xdmf(mesh: Mesh, m, temps: list[str]) -> None:
    write_xdmf(m, temps[0])


def _write_gmsh(mesh: Mesh, m, temps: list[str]) -> None:
    write_gmsh(mesh.material_names, m, temps[0])


def _write_node_ele(mesh: Mesh, m, temps: list[str]) -> None:
    write_node_ele(temps[0], temps[1], m.points, m.cells[0].data, m.cell_data["material"][0],
                   mesh.cell_data.get("quality"))


#: suffix -> writer(mesh, the meshio mesh in x, y(, z) order, temporary paths of targets)
_WRITERS = {".vtk": _write_vtk, ".xdmf": _write_xdmf, ".msh": _write_gmsh,
            ".node": _write_node_ele, ".ele": _write_node_ele}


# ----------------------------------------------------------------------------- reading


def read_mesh(path) -> Mesh:
    """Read a mesh written by `write_mesh` (or a compatible file) back into a `Mesh`.

    Parameters
    ----------
    path : str or Path
        Any suffix `write_mesh` writes; for Triangle/TetGen either ``.node`` or ``.ele``.

    Returns
    -------
    Mesh
        Points back in numpy axis order (plane, row, col), 2-D when the file holds
        triangles with z = 0; cells positively oriented there; ``material`` from the
        ``material`` array, Gmsh physical groups, Abaqus element sets or the
        Triangle/TetGen region attribute (0 for every element when the file has none,
        and then ``info["has_material"]`` is False); other per-cell arrays as stored. ``spacing``
        and ``shape`` are unknown (empty). Cell order may differ from the written mesh
        (Gmsh groups cells by material).
    """
    p = Path(path)
    if not p.exists() and p.suffix.lower() not in (".node", ".ele"):
        raise FileNotFoundError(f"no mesh file at {p}; check the path.")
    suffix = p.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(
            f"cannot read a mesh from {p.name!r}: unknown suffix {suffix!r}; use one of "
            f"{', '.join(MESH_SUFFIXES)}."
        )
    names: dict[int, str] = {}
    if suffix in (".node", ".ele"):
        points, cells, attributes = read_node_ele(p)
        material = attributes.pop("material", None)
        cell_data = attributes
    else:
        points, cells, material, cell_data, names = _read_meshio(p, suffix)
    if points.shape[1] == 3 and cells.shape[1] == 3:
        if np.any(points[:, 2] != 0):
            raise ValueError(
                f"{p} holds triangles in 3-D space; only flat 2-D meshes are supported."
            )
        points = points[:, :2]
    points = np.ascontiguousarray(points[:, ::-1], dtype=np.float64)
    cells = _orient_positive(points, cells)
    has_material = material is not None
    if material is None:
        material = np.zeros(len(cells), dtype=np.int64)
    return Mesh(
        points=points,
        cells=cells,
        material=np.rint(material).astype(np.int64),
        cell_data={k: np.asarray(v) for k, v in cell_data.items()},
        material_names=names,
        info={"source": str(p), "has_material": has_material},
    )


def _read_meshio(p: Path, suffix: str):
    import meshio

    fmt = {".vtu": "vtu", ".vtk": "vtk", ".xdmf": "xdmf", ".msh": "gmsh", ".inp": "abaqus"}[suffix]
    if fmt == "xdmf":
        require_h5py("read")
    try:
        m = meshio.read(p, file_format=fmt)
    except (meshio.ReadError, KeyError, IndexError) as exc:
        raise ValueError(f"cannot read {p} as a {suffix} mesh: {exc!r}") from exc
    keep = [i for i, block in enumerate(m.cells) if block.type in ("triangle", "tetra")]
    if not keep or len({m.cells[i].type for i in keep}) != 1:
        raise ValueError(
            f"{p} must hold triangles or tetrahedra (one kind); found "
            f"{sorted({b.type for b in m.cells})}."
        )
    cells = np.concatenate([m.cells[i].data for i in keep]).astype(np.intp)
    cell_data = {
        key: np.concatenate([np.asarray(blocks[i]) for i in keep])
        for key, blocks in m.cell_data.items()
        if not key.startswith("gmsh:")
    }
    names: dict[int, str] = {}
    material = cell_data.pop("material", None)
    if fmt == "gmsh":
        names, physical_material = gmsh_materials(m, keep)
        if material is None:
            material = physical_material
    elif fmt == "abaqus" and m.cell_sets:
        names, material = abaqus_materials(p, m, keep, len(cells))
    return np.asarray(m.points, dtype=np.float64), cells, material, cell_data, names
