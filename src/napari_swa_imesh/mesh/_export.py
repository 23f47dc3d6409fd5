"""Writing and reading meshes in the formats finite-element users expect.

Everything goes through meshio except Triangle/TetGen ``.node``/``.ele`` (see
``_triangle_tetgen``). Exported coordinates are x, y(, z) = column, row(, plane), the
reverse of the numpy axis order the ``Mesh`` keeps; each cell is reordered so that its
signed volume stays positive in those coordinates.

What each format holds
----------------------
========  ==========================================================================
``.vtu``  VTK XML (zlib); points padded to z = 0 in 2-D; every per-cell array.
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

import re
from pathlib import Path

import numpy as np

from ..io import atomic_write, check_writable
from ._triangle_tetgen import format_rows, read_node_ele, write_node_ele
from ._types import Mesh

__all__ = ["to_meshio", "write_mesh", "read_mesh", "mesh_output_paths", "MESH_SUFFIXES"]

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

_CELL_TYPE = {2: "triangle", 3: "tetra"}
_ABAQUS_TYPE = {2: "CPS3", 3: "C3D4"}
_NAME_NOTE = "** swa-imesh material"  # Abaqus comment line: "<note> <id> <set name>"


# ----------------------------------------------------------------------------- helpers


def _signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(M,) determinant of the edge vectors of each cell (d! times its signed volume)."""
    corners = points[cells]  # (M, d+1, d)
    edges = corners[:, 1:, :] - corners[:, :1, :]  # (M, d, d), one edge per row
    return np.linalg.det(edges)


def _orient_positive(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Copy of `cells` with the first two corners swapped where the volume is negative."""
    cells = np.array(cells, dtype=np.intp, copy=True)
    flip = _signed_volumes(points, cells) < 0
    cells[flip, 0], cells[flip, 1] = cells[flip, 1], cells[flip, 0].copy()
    return cells


def _check_mesh_arg(mesh) -> None:
    """A `Mesh` (which checked its own arrays when built) with something to write."""
    if not isinstance(mesh, Mesh):
        raise TypeError(
            f"expected a napari_swa_imesh Mesh (from mesh_labels or read_mesh); got "
            f"{type(mesh).__name__}."
        )
    if mesh.n_cells == 0:
        raise ValueError("the mesh has no elements; there is nothing to write.")


def _material_names(mesh: Mesh, materials: np.ndarray) -> dict[int, str]:
    """Name of each material present: ``mesh.material_names`` or ``material_<id>``."""
    names = {int(m): str(mesh.material_names.get(int(m), f"material_{int(m)}")) for m in materials}
    seen: dict[str, int] = {}
    for m, name in names.items():
        if not name.strip() or '"' in name or "\n" in name:
            raise ValueError(
                f"material {m} has name {name!r}; names must be non-empty text without "
                "quotes or line breaks."
            )
        if name in seen:
            raise ValueError(
                f"materials {seen[name]} and {m} share the name {name!r}; give each "
                "material its own name."
            )
        seen[name] = m
    return names


def _abaqus_set_names(names: dict[int, str]) -> dict[int, str]:
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


def _gmsh_tags(materials: np.ndarray) -> dict[int, int]:
    """Physical tag per material: its id, except 0 (Gmsh tags are positive) -> max+1."""
    top = int(materials.max())
    return {int(m): (int(m) if m > 0 else top + 1) for m in materials}


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
    points = np.ascontiguousarray(np.asarray(mesh.points, dtype=np.float64)[:, ::-1])
    cells = _orient_positive(points, mesh.cells)
    cell_data = {"material": [np.asarray(mesh.material, dtype=np.int64)]}
    for key, values in mesh.cell_data.items():
        values = np.asarray(values)
        # every writer takes int64/float64; some reject int8 or bool (XDMF as XML)
        kind = values.dtype.kind
        cell_data[key] = [values.astype(np.int64 if kind in "biu" else np.float64)]
    return meshio.Mesh(points, [(_CELL_TYPE[mesh.ndim], cells)], cell_data=cell_data)


def _padded(m):
    """The same meshio mesh with 2-D points given z = 0 (VTK formats need 3-D points)."""
    import meshio

    if m.points.shape[1] == 3:
        return m
    points = np.column_stack([m.points, np.zeros(len(m.points))])
    return meshio.Mesh(points, m.cells, cell_data=m.cell_data)


def _gmsh_mesh(mesh: Mesh, m):
    """One cell block, entity and named physical group per material.

    Returns the tagged meshio mesh and the per-cell arrays in its cell order.
    """
    import meshio
    import scipy.sparse as sp
    from scipy.sparse.csgraph import maximum_bipartite_matching

    dim = mesh.ndim
    cells = m.cells[0].data
    material = m.cell_data["material"][0]
    materials = np.unique(material)
    names = _material_names(mesh, materials)
    tags = _gmsh_tags(materials)
    blocks = [material == mat for mat in materials]

    # one entity per material, tagged like its physical group
    block_tags = [np.full(b.sum(), tags[int(mat)]) for mat, b in zip(materials, blocks)]
    cell_data = {"gmsh:physical": block_tags, "gmsh:geometrical": block_tags}
    field_data = {names[int(mat)]: np.array([tags[int(mat)], dim]) for mat in materials}

    # Gmsh 4 keeps physical tags on entities, and meshio writes an entity only if some
    # node is classified on it, so every material block needs a node of its own: a
    # maximum bipartite matching (blocks x nodes) finds one for each.
    n_points = len(m.points)
    block_of_cell = np.searchsorted(materials, material)  # (M,)
    incidence = sp.csr_matrix(
        (np.ones(cells.size, dtype=np.int8),
         (np.repeat(block_of_cell, cells.shape[1]), cells.ravel())),
        shape=(len(materials), n_points),
    )
    owner = maximum_bipartite_matching(incidence, perm_type="column")  # (K,) node or -1
    if (owner < 0).any():
        raise ValueError(
            "cannot write Gmsh 4.1 physical groups: some materials have too few nodes of "
            "their own to be told apart; write .vtu or .xdmf instead."
        )
    node_block = np.zeros(n_points, dtype=np.intp)
    node_block[cells.ravel()] = np.repeat(block_of_cell, cells.shape[1])
    node_block[owner] = np.arange(len(materials))
    entity_of_block = np.array([tags[int(mat)] for mat in materials])
    dim_tags = np.column_stack([np.full(n_points, dim), entity_of_block[node_block]])

    tagged = meshio.Mesh(
        m.points,
        [(_CELL_TYPE[dim], cells[b]) for b in blocks],
        cell_data=cell_data,
        point_data={"gmsh:dim_tags": dim_tags},
        field_data=field_data,
    )
    # element tags run 1..M through the blocks in order, so the data follow that order
    order = np.concatenate([np.flatnonzero(b) for b in blocks])
    element_data = {key: values[0][order] for key, values in m.cell_data.items()}
    return tagged, element_data


def _append_gmsh_element_data(path: str, element_data: dict[str, np.ndarray]) -> None:
    """Append one ``$ElementData`` section per array (1 component, time step 0).

    meshio 5.3 writes ASCII data with ``repr``, which numpy 2 turns into
    ``np.float64(...)``, so we write these sections ourselves.
    """
    with open(path, "a") as fh:
        for name, values in element_data.items():
            values = np.asarray(values)
            fh.write(f'$ElementData\n1\n"{name}"\n1\n0.0\n3\n0\n1\n{len(values)}\n')
            tags = np.arange(1, len(values) + 1)[:, None]
            if values.dtype.kind in "iu":
                fh.write(format_rows(np.column_stack([tags, values])))
            else:
                fh.write(format_rows(tags, values[:, None]))
            fh.write("$EndElementData\n")


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


def write_mesh(mesh: Mesh, path, *, force: bool = False) -> list[Path]:
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
    targets = mesh_output_paths(path, force=force)
    with atomic_write(targets, force=force) as temps:
        write_mesh_to(mesh, temps)
    return targets


def write_mesh_to(mesh: Mesh, temps: list[Path]) -> None:
    """Write `mesh` to the temporary paths that :func:`atomic_write` gave for the targets
    of :func:`mesh_output_paths` (same names, so twins name each other right)."""
    _write_files(mesh, temps[0].suffix.lower(), [str(t) for t in temps], temps)


def _write_files(mesh: Mesh, suffix: str, temps: list[str], targets: list[Path]) -> None:
    import meshio

    m = to_meshio(mesh)
    try:
        _write_format(mesh, m, suffix, temps, targets)
    except (meshio.WriteError, KeyError) as exc:  # meshio's own failures, as one clear line
        raise ValueError(f"meshio could not write {targets[0].name}: {exc}") from exc


def _write_format(mesh: Mesh, m, suffix: str, temps: list[str], targets: list[Path]) -> None:
    import meshio

    if suffix == ".vtu":
        meshio.write(temps[0], _padded(m), file_format="vtu")
    elif suffix == ".vtk":
        meshio.write(temps[0], _padded(m), file_format="vtk42", binary=True)
    elif suffix == ".xdmf":
        _require_h5py("write")
        meshio.write(temps[0], m, file_format="xdmf", data_format="HDF")
    elif suffix == ".msh":
        tagged, element_data = _gmsh_mesh(mesh, m)
        meshio.write(temps[0], tagged, file_format="gmsh", binary=False)
        _append_gmsh_element_data(temps[0], element_data)
    elif suffix == ".inp":
        _write_abaqus(mesh, m, temps[0])
    else:
        quality = mesh.cell_data.get("quality")
        write_node_ele(temps[0], temps[1], m.points, m.cells[0].data,
                       m.cell_data["material"][0], quality)


def _require_h5py(verb: str) -> None:
    try:
        import h5py  # noqa: F401
    except ImportError:
        raise ValueError(
            f"cannot {verb} .xdmf: meshio's XDMF support needs the h5py package, which is "
            "not installed; `pip install h5py`, or choose .vtu."
        ) from None


def _write_abaqus(mesh: Mesh, m, tmp: str) -> None:
    import meshio

    material = m.cell_data["material"][0]
    materials = np.unique(material)
    set_names = _abaqus_set_names(_material_names(mesh, materials))
    cell_sets = {set_names[int(mat)]: [np.flatnonzero(material == mat)] for mat in materials}
    out = meshio.Mesh(m.points, m.cells, cell_sets=cell_sets)
    # 13 significant digits keep every number within 20 characters, the field width
    # CalculiX (the common free reader of .inp) takes; longer fields are rejected there
    meshio.write(tmp, out, file_format="abaqus", float_fmt=".12e")
    # meshio names triangles R3D3 (a rigid surface); a 2-D solid wants a continuum
    # element, and the material ids ride along as comments so read_mesh recovers them.
    text = Path(tmp).read_text()
    text = re.sub(r"(?im)^\*ELEMENT, TYPE=\w+$", f"*ELEMENT, TYPE={_ABAQUS_TYPE[mesh.ndim]}", text)
    notes = "".join(f"{_NAME_NOTE} {mat} {name}\n" for mat, name in set_names.items())
    Path(tmp).write_text(notes + text)


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
        Triangle/TetGen region attribute; other per-cell arrays as stored. ``spacing``
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
        material = attributes.pop("material", np.zeros(len(cells)))
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
    return Mesh(
        points=points,
        cells=cells,
        material=np.rint(material).astype(np.int64),
        cell_data={k: np.asarray(v) for k, v in cell_data.items()},
        material_names=names,
        info={"source": str(p)},
    )


def _read_meshio(p: Path, suffix: str):
    import meshio

    fmt = {".vtu": "vtu", ".vtk": "vtk", ".xdmf": "xdmf", ".msh": "gmsh", ".inp": "abaqus"}[suffix]
    if fmt == "xdmf":
        _require_h5py("read")
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
        names, physical_material = _gmsh_names(m, keep)
        if material is None:
            material = physical_material
    elif fmt == "abaqus":
        names, material = _abaqus_materials(p, m, keep, len(cells))
    if material is None:
        material = np.zeros(len(cells), dtype=np.int64)
    return np.asarray(m.points, dtype=np.float64), cells, material, cell_data, names


def _gmsh_names(m, keep):
    """Material names and (from physical tags) material ids of a Gmsh file."""
    if "gmsh:physical" not in m.cell_data:
        return {}, None
    physical = np.concatenate([m.cell_data["gmsh:physical"][i] for i in keep]).astype(np.int64)
    material_of_cell = m.cell_data.get("material")
    tag_to_name = {int(tag): name for name, (tag, _dim) in m.field_data.items()}
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


def _abaqus_materials(p: Path, m, keep, n_cells):
    """Material ids from our comment lines (or ``material_<id>`` set names, else 1..K)."""
    ids: dict[str, int] = {}
    with open(p) as fh:
        for line in fh:
            if not line.startswith("**"):
                break
            if line.startswith(_NAME_NOTE):
                mat, name = line[len(_NAME_NOTE) :].split()
                ids[name] = int(mat)
    material = np.zeros(n_cells, dtype=np.int64)
    names: dict[int, str] = {}
    offsets = np.cumsum([0] + [len(m.cells[i].data) for i in keep])
    for k, (name, blocks) in enumerate(m.cell_sets.items()):
        found = re.fullmatch(r"material_(\d+)", name)
        mat = ids.get(name, int(found.group(1)) if found else k + 1)
        names[mat] = name
        for j, i in enumerate(keep):
            material[offsets[j] + np.asarray(blocks[i], dtype=np.intp)] = mat
    return names, material
