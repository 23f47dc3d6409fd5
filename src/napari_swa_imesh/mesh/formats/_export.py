"""Writing meshes in the formats finite-element users expect: the dispatcher.

This module checks the options once (before any meshing, when the command line asks),
prepares the mesh once (``_prepare.ExportMesh``: the files' frame, order 1 or 2, the facet
groups asked for), looks the format up by suffix in the registry (``_registry``: one
record per format, the only place that knows suffixes) and sends every write through
``io.atomic_write``; each format keeps its layout in a module of its own (``_gmsh``,
``_abaqus``, ``_vtu`` and ``_facet_vtu``, ``_xdmf``, ``_triangle_tetgen``). Exported
coordinates are x, y(, z) = column, row(, plane) (``_common.export_points``); each cell is
reordered so that its signed volume stays positive there. Reading is in ``_read``.

What each format holds
----------------------
========  ==========================================================================
``.vtu``  VTK XML (raw binary, streamed); points padded to z = 0 in 2-D; every per-cell array
          (64-bit integers as Int32 when every value fits, see ``_vtu``); facet groups
          in ``<stem>_facets.vtu`` (cell data ``group`` and ``owner``, names in field
          data; see ``_facet_vtu``).
``.vtk``  legacy VTK 4.2 (readable by any VTK); points padded; every per-cell array;
          no facet groups.
``.msh``  Gmsh 4.1, binary (or ASCII with ``binary=False``); one physical group of
          dimension d per material and one of dimension d-1 per facet group, named
          after them; every per-cell array as ``$ElementData`` (see ``_gmsh``).
``.xdmf`` XDMF 3 with its arrays in a ``.h5`` beside it (same stem; needs h5py; meshio's
          layout, written block by block by ``_xdmf``); every array; facet groups in
          ``<stem>_xdmf_facets.vtu``, laid out as for ``.vtu``.
``.inp``  Abaqus; one ``*ELSET`` per material; ``*NSET`` and element-face ``*SURFACE``
          per facet group; no per-cell arrays (see ``_abaqus``).
``.node`` Triangle (2-D; attributes material, quality) or TetGen (3-D; region
``.ele``  attribute material); both files are written, with the same stem, and the
          facet groups as boundary markers in a Triangle ``.poly`` / TetGen ``.face``.
========  ==========================================================================

At second order (``order=2``) every format gets 6-node triangles / 10-node tetrahedra
with one node at the midpoint of each edge (``_order2``), and facets of second order.
"""

from __future__ import annotations

from pathlib import Path

from ..._validation import OptionError
from ...io import atomic_write, check_writable
from ..model._types import Mesh
from ._abaqus import ABAQUS_ELEMENTS
from ._common import export_points
from ._legacy_vtk import _meshio_of
from ._prepare import ORDERS, ExportMesh, check_facet_selection
from ._read import read_mesh
from ._registry import _FACETS_STEM as FACETS_STEM
from ._registry import MESH_SUFFIXES, mesh_format, mesh_formats
from ._vtu import write_vtu

__all__ = ["to_meshio", "write_mesh", "write_mesh_vtu", "read_mesh", "mesh_output_paths",
           "check_write_options", "MESH_SUFFIXES"]


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
    _check_mesh_arg(mesh)
    return _meshio_of(ExportMesh(mesh, groups="none"))


# ----------------------------------------------------------------------------- options


def check_write_options(path, *, order: int = 1, binary: bool = True, facet_groups="all",
                        abaqus_elements: str = "mechanical", ndim: int | None = None):
    """Check the options of :func:`write_mesh` for `path` before any work.

    Everything that can be known without the mesh is checked here (the facet-group names
    of a mesh only once it exists); `ndim` may be None when the dimension is not known yet.

    Returns
    -------
    "all", "none" or tuple of str
        The facet-group selection in one form.

    Raises
    ------
    ValueError
        Unknown suffix, order, element kind or facet group; ASCII asked for a format
        other than ``.msh``; facet groups named for legacy ``.vtk``, which holds none.
    """
    fmt = mesh_format(path)
    if fmt.requires is not None:
        fmt.requires("write")       # names the extra (e.g. [xdmf]) before any work
    if abaqus_elements not in ABAQUS_ELEMENTS:
        raise ValueError(f"abaqus_elements must be one of {', '.join(ABAQUS_ELEMENTS)}, not "
                         f"{abaqus_elements!r}.")
    if isinstance(order, bool) or order not in ORDERS:
        raise ValueError(f"order must be 1 (linear) or 2 (mid-edge nodes), not {order!r}.")
    if not isinstance(binary, bool):
        raise TypeError(f"binary must be True or False, not {binary!r}.")
    if not binary and "binary" not in fmt.options:
        ascii_ = " or ".join(f.suffix for f in mesh_formats() if "binary" in f.options)
        raise ValueError(f"binary=False (ASCII) applies to {ascii_} only; "
                         f"{fmt.files(Path(path))[0].suffix.lower()} has one encoding, so "
                         f"leave it out or write {ascii_}.")
    selection = check_facet_selection(facet_groups, ndim)
    if not fmt.facet_groups and isinstance(selection, tuple):
        raise OptionError("facet_groups", f"{fmt.called} holds no facet groups; write "
                          f"{_with_groups()}, or {{drop}}.", drop="leave the facet groups out")
    return selection


def _with_groups() -> str:
    """The formats that hold facet groups, as the refusal of one that does not names them:
    ``.vtu (its groups go to <stem>_facets.vtu) or .msh``."""
    vtu, msh = (next(f for f in mesh_formats() if f.name == n) for n in ("vtu", "gmsh"))
    return f"{vtu.suffix} (its groups go to <stem>{FACETS_STEM}{vtu.suffix}) or {msh.suffix}"


def mesh_output_paths(path, *, force: bool = False, facet_groups="all",
                      ndim: int | None = None) -> list[Path]:
    """The files `write_mesh` would write for `path`, after checking it may write them.

    Lets a caller fail fast (before meshing) on a bad suffix or an existing file.

    Parameters
    ----------
    path : str or Path
        As for :func:`write_mesh`.
    force : bool
        Whether existing files may be replaced.
    facet_groups : "all", "none" or list of str
        As for :func:`write_mesh`: unless ``"none"``, ``.vtu`` adds
        ``<stem>_facets.vtu``, ``.xdmf`` ``<stem>_xdmf_facets.vtu``, and ``.node``/``.ele``
        add ``.poly`` (2-D) or ``.face`` (3-D).
    ndim : int, optional
        Dimension of the mesh; without it the ``.poly``/``.face`` file is not listed.

    Returns
    -------
    list of Path
        The main file first, then its twin (``.ele``, ``.h5``), then the facet file.

    Raises
    ------
    ValueError
        Unknown suffix (the message lists the supported ones).
    FileExistsError
        A target exists and `force` is false.
    FileNotFoundError
        The target folder does not exist.
    """
    targets = mesh_format(path).targets(path, facet_groups=facet_groups, ndim=ndim)
    for target in targets:
        check_writable(target, force=force)
    return targets


# ----------------------------------------------------------------------------- writing


def write_mesh(mesh: Mesh, path, *, force: bool = False,
               abaqus_elements: str = "mechanical", order: int = 1, binary: bool = True,
               facet_groups="all") -> list[Path]:
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
        Element types of an ``.inp``: continuum (``CPS3``/``C3D4``, order 2
        ``CPS6``/``C3D10``) or heat transfer (``DC2D3``/``DC3D4``, order 2
        ``DC2D6``/``DC3D10``, for ``*HEAT TRANSFER``).
    order : {1, 2}
        2 adds a node at the midpoint of every edge (shared by the elements around it):
        6-node triangles, 10-node tetrahedra, in each format's node order.
    binary : bool
        ``.msh`` only: Gmsh's binary encoding (default) or ASCII (``False``).
    facet_groups : "all", "none" or list of str
        Which facet groups (:func:`facet_groups`) to write: box sides, interfaces and
        exteriors by name, or patterns such as ``"interface_*"``. Every name must be a
        group of this mesh. ``.vtu`` gets them in ``<stem>_facets.vtu``, ``.xdmf`` in
        ``<stem>_xdmf_facets.vtu`` (:func:`._registry.facets_companion`; two formats of
        one mesh can share a folder), ``.node``/``.ele`` in a ``.poly``/``.face`` file;
        legacy ``.vtk`` holds none.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        Unknown suffix or option, a facet group this mesh does not have, or a mesh that
        cannot be written.
    FileExistsError
        A target exists and `force` is false (all targets are checked first).

    Notes
    -----
    Every file is written under a temporary name in the target folder and then moved
    into place, so a failed write never leaves a half file where the user's was.
    """
    _check_mesh_arg(mesh)
    selection = check_write_options(path, order=order, binary=binary,
                                    facet_groups=facet_groups,
                                    abaqus_elements=abaqus_elements, ndim=mesh.ndim)
    fmt = mesh_format(path)
    if not fmt.facet_groups:
        selection = "none"
    targets = mesh_output_paths(path, force=force, facet_groups=selection, ndim=mesh.ndim)
    if fmt.requires is not None:
        fmt.requires("write")
    ex = ExportMesh(mesh, order=int(order), groups=selection)  # unknown groups fail here
    options = {"binary": binary, "abaqus_elements": abaqus_elements}
    with atomic_write(targets, force=force) as temps:
        fmt.write(ex, temps, **{k: v for k, v in options.items() if k in fmt.options})
    return targets


def write_mesh_vtu(mesh: Mesh, path, *, point_data: dict | None = None,
                   cell_data: dict | None = None) -> None:
    """Write `mesh` to `path` as ``.vtu`` with extra per-point and per-cell arrays.

    The writer behind :func:`write_mesh`'s ``.vtu`` (x, y(, z) order, cells positive
    there, ``material`` and the mesh's own arrays in their dtypes, 64-bit integers as
    Int32 when every value fits; see :mod:`._vtu`), for callers that add fields and write
    through :func:`~napari_swa_imesh.io.atomic_write` themselves. Vectors in
    `cell_data`/`point_data` must already be in x, y(, z) order.
    """
    points = export_points(mesh)
    data = {"material": mesh.material, **mesh.cell_data, **(cell_data or {})}
    write_vtu(path, points, mesh.cells, cell_data=data, point_data=point_data, orient=True)
