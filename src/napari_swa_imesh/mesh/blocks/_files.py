"""Files of a block-wise mesh: one piece per block, and the index that names them.

Layout of ``OUT.pvtu`` (partitioned VTK, ParaView's convention): the index ``OUT.pvtu``
and a folder ``OUT/`` beside it holding ``OUT_<i>.vtu`` (the piece of block ``i``) and
``OUT_<i>_facets.vtu`` (its facet groups, the ``_facet_vtu`` layout: same points, one
triangle per facet, cell data ``group`` and ``owner``, names in ``<FieldData>``). For
``OUT.xdmf`` the folder holds ``OUT_<i>.h5`` (the piece and its groups as
``facets/<name>``, ``owners/<name>``) and ``OUT_<i>.xdmf`` (that piece as one grid)
instead, and the index is an XDMF spatial collection of one grid per piece.

Every piece carries: points in the files' frame (x = column, y = row, z = plane, times the
spacing); cell data ``material``, ``quality`` (radius-to-edge) and ``level``; point data
``global_id``, the vertex's key in the image's corner lattice, so a vertex on a shared
face has one id in every piece that holds it (Int32 when the lattice has fewer than 2**31
points, else Float64, exact to 2**53, so every piece declares one type). Blocks with no
meshed element have no piece.

Who reads the pieces: VTK's ``XMLPUnstructuredGridReader`` reads the ``.pvtu`` (pyvista,
ParaView; under MPI, ``pvbatch`` gives each rank its pieces) and VTK's ``vtkXdmfReader``
(ParaView) the XDMF index, as a multiblock; meshio reads one grid per file, so it reads
each piece (``.vtu`` or the piece's own ``.xdmf``), not an index, and :func:`read_pvtu`
(``read_mesh``) joins the pieces of either index. An MPI solver reads its rank's pieces
with any ``.vtu``/HDF5 reader and joins shared vertices by ``global_id``, no renumbering
or halo exchange needed to assemble. FEniCSx/dolfinx partitions a mesh it reads from one
XDMF grid itself: for it, merge (``read_mesh`` then ``write_mesh``) while the mesh fits
one process. The reading by pyvista, VTK's XDMF reader and meshio is tested.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..formats._registry import PARTITIONED, PVTU, XDMF_INDEX, facets_companion
from ..formats._vtu import write_vtu
from ._quadratic import quadratic_arrays

__all__ = [
    "id_dtype",
    "is_xdmf_index",
    "piece_names",
    "read_pvtu",
    "read_pvtu_groups",
    "write_piece_h5",
    "write_piece_vtu",
    "write_pvtu",
    "write_xdmf_index",
]

_VTK_NAME = {np.dtype(np.int32): "Int32", np.dtype(np.float64): "Float64",
             np.dtype(np.int8): "Int8"}


def id_dtype(n_lattice: int) -> np.dtype:
    """The dtype global ids are written in: int32 below 2**31 lattice points, else float64."""
    return np.dtype(np.int32) if n_lattice < 2**31 else np.dtype(np.float64)


def piece_names(output, number: int) -> tuple[str, str, str]:
    """(piece, facets companion, h5) file names of piece `number` of `output`.

    Examples
    --------
    >>> piece_names("run/brain.pvtu", 3)
    ('brain_3.vtu', 'brain_3_facets.vtu', 'brain_3.h5')
    """
    stem = Path(output).stem
    piece = Path(f"{stem}_{number}").with_suffix(PARTITIONED[PVTU])
    return (piece.name, facets_companion(piece).name,
            piece.with_suffix(PARTITIONED[XDMF_INDEX]).name)


def _file_arrays(piece, spacing, ids: np.dtype, mat: np.dtype, order: int = 1,
                 shape=None):
    """Points (x, y(, z)), cells, cell data, point data and the facet groups' facets
    (name -> nodes) in the files' frame; reversing the axes is an odd permutation (2-D
    and 3-D), so two corners of every cell (and facet) are swapped to keep it positively
    oriented. At `order` 2 the mid-edge nodes follow (``_quadratic``; `shape`: the
    lattice's)."""
    d = piece.points.shape[1]
    swap = [1, 0] + list(range(2, d + 1))
    flip = [1, 0] + list(range(2, d))
    names = list(piece.groups)
    points, gid, cells = piece.points, piece.gid, piece.cells[:, swap]
    facets = [piece.groups[n][0][:, flip] for n in names]
    if order == 2:
        points, gid, cells, facets = quadratic_arrays(points, gid, cells, facets, shape)
    pts = (points * np.asarray(spacing, float))[:, ::-1]
    return pts, cells, {
        "material": piece.material.astype(mat), "quality": piece.quality.astype(np.float64),
        "level": piece.level.astype(np.int8)}, {"global_id": gid.astype(ids)}, dict(
            zip(names, facets))


def write_piece_vtu(folder: Path, output, number: int, piece, spacing, group_ids: dict,
                    ids: np.dtype, mat: np.dtype, order: int = 1, shape=None) -> int:
    """Write piece `number` and its facet companion into `folder` (at `order` 2 with
    mid-edge nodes: `shape` is the lattice's); returns the nodes written."""
    name, facets_name, _ = piece_names(output, number)
    pts, cells, cell_data, point_data, facet_nodes = _file_arrays(
        piece, spacing, ids, mat, order, shape)
    write_vtu(folder / name, pts, cells, cell_data=cell_data, point_data=point_data)
    d = pts.shape[1]
    names = [n for n in group_ids if n in piece.groups]
    width = d if order == 1 else 3 * d - 3
    facets = np.concatenate([np.zeros((0, width), np.intp)] + [facet_nodes[n] for n in names])
    group = np.concatenate([np.zeros(0, np.int32)]
                           + [np.full(len(piece.groups[n][1]), group_ids[n], np.int32)
                              for n in names])
    owner = np.concatenate([np.zeros(0, np.int64)] + [piece.groups[n][1] for n in names])
    write_vtu(folder / facets_name, pts, facets, cell_data={"group": group, "owner": owner},
              field_data={n: [group_ids[n]] for n in group_ids},
              cell_type={(2, 1): 3, (2, 2): 21, (3, 1): 5, (3, 2): 22}[(d, order)])
    return len(pts)


def write_piece_h5(folder: Path, output, number: int, piece, spacing, group_ids: dict,
                   ids: np.dtype, mat: np.dtype, order: int = 1, shape=None) -> int:
    """Write piece `number` as one HDF5 file: points, cells, cell and point data, and each
    facet group as ``facets/<name>`` (vertex ids) and ``owners/<name>``; returns the
    nodes written."""
    from ..._atomic import hdf5_file

    _, _, h5_name = piece_names(output, number)
    pts, cells, cell_data, point_data, facet_nodes = _file_arrays(
        piece, spacing, ids, mat, order, shape)
    d = pts.shape[1]
    with hdf5_file(folder / h5_name) as h5:
        h5["points"] = pts
        h5["cells"] = cells.astype(np.int64)
        for name, values in {**cell_data, **point_data}.items():
            h5[name] = values
        for name, (_, o) in piece.groups.items():
            h5[f"facets/{name}"] = facet_nodes[name].astype(np.int64)
            h5[f"owners/{name}"] = o.astype(np.int64)
            h5[f"facets/{name}"].attrs["group_id"] = group_ids[name]
    # the piece alone as one grid: what meshio (one grid per file) and solvers reading
    # their rank's pieces open
    (folder / Path(h5_name).with_suffix(XDMF_INDEX)).write_text(
        '<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain>'
        + _grid_xml("", h5_name, len(pts), len(cells), d, ids, mat, cells.shape[1])
        + "</Domain></Xdmf>\n")
    return len(pts)


def _pdata(section: str, arrays: dict) -> str:
    tags = "".join(f'<PDataArray type="{_VTK_NAME[np.dtype(t)]}" Name={quoteattr(n)}/>'
                   for n, t in arrays.items())
    return f"<{section}>{tags}</{section}>"


def write_pvtu(path, folder_name: str, sources: list[str], ids: np.dtype, mat: np.dtype) -> None:
    """Write the ``.pvtu`` index naming the pieces ``folder_name/<source>``."""
    pieces = "".join(f"<Piece Source={quoteattr(f'{folder_name}/{s}')}/>" for s in sources)
    text = ('<?xml version="1.0"?>\n<VTKFile type="PUnstructuredGrid" version="1.0" '
            f'byte_order="{"LittleEndian" if np.little_endian else "BigEndian"}" '
            'header_type="UInt64"><PUnstructuredGrid GhostLevel="0">'
            + _pdata("PCellData", {"material": mat, "quality": np.float64, "level": np.int8})
            + _pdata("PPointData", {"global_id": ids})
            + '<PPoints><PDataArray type="Float64" NumberOfComponents="3"/></PPoints>'
            + pieces + "</PUnstructuredGrid></VTKFile>\n")
    Path(path).write_text(text)


def _grid_xml(prefix: str, h5: str, n_pts: int, n_cells: int, d: int, ids: np.dtype,
              mat: np.dtype, nodes: int | None = None) -> str:
    """One XDMF ``<Grid>`` of the piece in `h5` (named ``prefix + h5`` from the file), of
    `nodes` per cell (default: linear)."""
    nodes = nodes or d + 1
    topo = {3: "Triangle", 4: "Tetrahedron", 6: "Triangle_6", 10: "Tetrahedron_10"}[nodes]
    geo = "XYZ" if d == 3 else "XY"
    num = {np.dtype(np.int32): ('Int', 4), np.dtype(np.float64): ('Float', 8),
           np.dtype(np.int8): ('Char', 1)}

    def item(name, dims, dtype):
        kind, prec = num[np.dtype(dtype)]
        return (f'<DataItem Dimensions="{dims}" NumberType="{kind}" Precision="{prec}" '
                f'Format="HDF">{prefix}{h5}:/{name}</DataItem>')

    attrs = "".join(
        f'<Attribute Name="{n}" AttributeType="Scalar" Center="{c}">'
        f'{item(n, m, t)}</Attribute>'
        for n, c, m, t in (("material", "Cell", n_cells, mat),
                           ("quality", "Cell", n_cells, np.float64),
                           ("level", "Cell", n_cells, np.int8),
                           ("global_id", "Node", n_pts, ids)))
    cells_item = (f'<DataItem Dimensions="{n_cells} {nodes}" NumberType="Int" '
                  f'Precision="8" Format="HDF">{prefix}{h5}:/cells</DataItem>')
    return (f'<Grid Name="{Path(h5).stem}" GridType="Uniform">'
            f'<Topology TopologyType="{topo}" NumberOfElements="{n_cells}">'
            f'{cells_item}</Topology><Geometry GeometryType="{geo}">'
            f'{item("points", f"{n_pts} {d}", np.float64)}</Geometry>'
            f'{attrs}</Grid>')


def write_xdmf_index(path, folder_name: str, pieces: list[tuple[str, int, int]], d: int,
                     ids: np.dtype, mat: np.dtype, nodes: int | None = None) -> None:
    """Write the XDMF index: a spatial collection of one grid per (h5 name, n_points,
    n_cells), of `nodes` per cell (default linear). VTK's ``vtkXdmfReader`` (ParaView)
    reads it as a multiblock; meshio reads one grid per file, so each piece also has its
    own ``.xdmf`` beside its ``.h5``."""
    grids = [_grid_xml(f"{folder_name}/", h5, n_pts, n_cells, d, ids, mat, nodes)
             for h5, n_pts, n_cells in pieces]
    Path(path).write_text('<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain>'
                          '<Grid Name="pieces" GridType="Collection" CollectionType="Spatial">'
                          + "".join(grids) + "</Grid></Domain></Xdmf>\n")


def is_xdmf_index(path) -> bool:
    """Whether `path` is the XDMF index of a block-wise mesh (a spatial collection of
    pieces), which :func:`read_pvtu` reads, not meshio.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    bool
    """
    try:
        with open(path, "rb") as f:
            head = f.read(400)
    except OSError:
        return False
    return b'<Grid Name="pieces" GridType="Collection" CollectionType="Spatial">' in head


def _sources(path: Path) -> list[Path]:
    """The files of the pieces an index names: the ``.vtu`` pieces of a ``.pvtu``, the
    one-grid ``.xdmf`` beside each ``.h5`` of an XDMF index."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"cannot read {path} as a block-wise mesh index: {exc}; write it "
                         "again with swa-imesh mesh.") from exc
    if path.suffix.lower() == PVTU:
        return [path.parent / p.attrib["Source"] for p in root.iter("Piece")]
    out = []
    for grid in root.iter("Grid"):
        if grid.attrib.get("GridType") == "Uniform":
            item = grid.find("./Geometry/DataItem")
            if item is None or not item.text:
                raise ValueError(f"{path} has a piece with no geometry; write it again with "
                                 "swa-imesh mesh.")
            h5 = item.text.strip().split(":")[0]
            out.append((path.parent / h5).with_suffix(XDMF_INDEX))
    return out


def _read_piece(p: Path):
    import meshio

    if not p.is_file():
        raise FileNotFoundError(f"the piece {p} named by the index is missing; copy the "
                                "whole folder with the index.")
    m = meshio.read(p, file_format="vtu" if p.suffix.lower() != XDMF_INDEX else "xdmf")
    cells = np.concatenate([c.data for c in m.cells])
    # second order: the corners (the mid-edge nodes follow them in every element)
    corners = {6: 3, 10: 4}.get(cells.shape[1], cells.shape[1])
    return m, cells[:, :corners]


def read_pvtu(path):
    """Read a block-wise mesh (its ``.pvtu`` or XDMF index) as one :class:`Mesh`
    (vertices joined by ``global_id``, in id order; elements piece by piece), each piece
    read by meshio.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Mesh
        Points in numpy axis order, ``material`` and ``quality``/``level`` cell data.
    """
    from ..formats._common import orient_positive
    from ..model._types import Mesh

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no mesh file at {path}; check the path.")
    gids, pts, cells, mats, data = [], [], [], [], {"quality": [], "level": []}
    offset = 0
    for src in _sources(path):
        m, c = _read_piece(src)
        if "global_id" not in m.point_data:
            raise ValueError(f"{src} has no global_id point data; it is not a piece of a "
                             "block-wise mesh.")
        gids.append(np.asarray(m.point_data["global_id"]).astype(np.int64).ravel())
        pts.append(m.points)
        cells.append(c + offset)
        offset += len(m.points)
        mats.append(np.concatenate(m.cell_data["material"]).ravel())
        for k, values in data.items():
            values.append(np.concatenate(m.cell_data[k]).ravel())
    if not gids:
        raise ValueError(f"{path} names no piece; the mesh is empty.")
    gid = np.concatenate(gids)
    joined = np.concatenate(cells)
    used = np.zeros(len(gid), bool)
    used[joined] = True
    if not used.all():
        # nodes no element corner uses (second order's mid-edge nodes) are left out
        gid = np.where(used, gid, -1)
    _, first, inverse = np.unique(gid, return_index=True, return_inverse=True)
    if gid.size and gid.min() < 0:
        first, inverse = first[1:], inverse - 1
    points = np.concatenate(pts)[first]
    d = 3 if points.shape[1] == 3 and (np.any(points[:, 2] != 0)
                                       or joined.shape[1] == 4) else 2
    points = np.ascontiguousarray(points[:, :d][:, ::-1], dtype=np.float64)
    cells = orient_positive(points, inverse[joined])
    return Mesh(points, cells, np.concatenate(mats).astype(np.int64),
                cell_data={k: np.concatenate(v) for k, v in data.items()},
                info={"source": str(path), "has_material": True, "pieces": len(gids)})


def read_pvtu_groups(path) -> dict[str, np.ndarray]:
    """The facet groups of a block-wise mesh: name -> (F, d) global vertex ids, each row
    sorted (orientation dropped), from the pieces' facet companions (``.pvtu``) or the
    ``facets/<name>`` datasets of their HDF5 files (XDMF index).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict of str to ndarray
    """
    import meshio

    out: dict[str, list] = {}
    path = Path(path)
    if path.suffix.lower() == XDMF_INDEX:
        import h5py

        for src in _sources(path):
            with h5py.File(src.with_suffix(PARTITIONED[XDMF_INDEX]), "r") as h5:
                gid = h5["global_id"][()].astype(np.int64).ravel()
                d = h5["points"].shape[1]                   # facets: their d corners
                for name in h5.get("facets", {}):
                    out.setdefault(name, []).append(
                        np.sort(gid[h5[f"facets/{name}"][()][:, :d]], axis=1))
        return {k: np.concatenate(v) for k, v in out.items()}
    for src in _sources(path):
        comp = facets_companion(src)
        with open(comp, "rb") as fh:
            if b'NumberOfCells="0"' in fh.read(1 << 16):   # the text header
                continue                   # a piece with no group facet (meshio fails)
        m = meshio.read(comp, file_format="vtu")
        gid = np.asarray(meshio.read(src, file_format="vtu").point_data["global_id"]
                         ).astype(np.int64).ravel()
        # second order (line3, triangle6): the corners come first
        facets = (np.concatenate([c.data[:, :{"line3": 2, "triangle6": 3}.get(c.type, 9)]
                                  for c in m.cells]) if m.cells else np.zeros((0, 3), int))
        group = np.concatenate(m.cell_data["group"]) if m.cells else np.zeros(0, int)
        names = {int(np.ravel(v)[0]): k for k, v in m.field_data.items()}
        for g in np.unique(group).tolist():
            out.setdefault(names[g], []).append(np.sort(gid[facets[group == g]], axis=1))
    return {k: np.concatenate(v) for k, v in out.items()}
