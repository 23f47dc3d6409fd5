"""The mesh file formats, one record each: the only module that knows their suffixes.

A :class:`MeshFormat` says which suffixes name a format, which files one write makes
(the main file and a twin: ``.node`` + ``.ele``, ``.xdmf`` + ``.h5``), the facet-group
companion file, what the format holds, the write options it takes, and how it is written
and read. The records are registered once, at the end of this module, in the order users
see them (as meshio's ``register_format``); the dispatchers (``write_mesh``,
``read_mesh``, ``mesh_output_paths``, the command line, the napari widgets) look a
suffix up with :func:`mesh_format` and know nothing else. A new format is one module (its
writer and reader) and one record here.

The writers and readers are imported when a file is written or read, not with the
package.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["MeshFormat", "MESH_SUFFIXES", "FACET_SUFFIX", "register_format", "mesh_format",
           "mesh_formats", "facets_companion", "node_ele_pair", "UnknownSuffixError"]


class UnknownSuffixError(ValueError):
    """A path whose suffix names no registered format (a ValueError saying which do)."""


@dataclass(frozen=True)
class MeshFormat:
    """One mesh file format.

    Attributes
    ----------
    name : str
        Short name (meshio's where it has one).
    suffixes : tuple of str
        Lower-case suffixes that name the format; ``suffixes[0]`` is its own.
    description : str
        One line for help texts and file dialogs.
    files : callable
        ``files(path) -> list of Path``: the main file and its twin, in write order.
    companion : callable or None
        ``companion(main, ndim) -> Path or None``: the file the facet groups go to
        (None: the main file holds them, or the dimension is unknown).
    facet_groups : bool
        Whether the format holds facet groups at all.
    options : frozenset of str
        Write options it takes beyond ``order`` and ``facet_groups`` (``"binary"``,
        ``"abaqus_elements"``).
    write : callable
        ``write(ex, temps, **options)``: the prepared mesh to the temporary paths of
        ``files`` (then of the companion).
    read : callable or None
        ``read(path) -> (points, cells, material or None, cell_data, names)``.
    label : str
        How a sentence names the format (default: its suffix).
    check_labels : callable or None
        ``check_labels(labels, exclude)``: a limit of the format on the label values,
        checked before meshing.
    requires : callable or None
        ``requires(action)``: ImportError naming what to install for "write" or "read".
    fields : bool
        Whether the format holds fields beside the mesh (point and cell data: a
        simulation's potentials and fluxes, written by ``simulate.write_field``).
    series : bool
        Whether it holds a time series of fields (``simulate.write_series``).
    """

    name: str
    suffixes: tuple[str, ...]
    description: str
    files: Callable[[Path], list[Path]]
    write: Callable
    read: Callable | None = None
    companion: Callable[[Path, int | None], Path | None] | None = None
    facet_groups: bool = True
    options: frozenset[str] = field(default_factory=frozenset)
    label: str = ""
    check_labels: Callable | None = None
    requires: Callable[[str], None] | None = None
    fields: bool = False
    series: bool = False

    @property
    def suffix(self) -> str:
        """The format's own suffix."""
        return self.suffixes[0]

    @property
    def called(self) -> str:
        """How a sentence names the format: `label`, else its suffix."""
        return self.label or self.suffix

    def targets(self, path, *, facet_groups="all", ndim: int | None = None) -> list[Path]:
        """The files a write of `path` makes: main, twin, then the facet companion
        (unless `facet_groups` is ``"none"`` or the format keeps them in the main file)."""
        path = Path(path)
        files = self.files(path)
        if facet_groups != "none" and self.companion is not None:
            extra = self.companion(files[0], ndim)
            if extra is not None:
                files.append(extra)
        return files


_FORMATS: dict[str, MeshFormat] = {}


def register_format(fmt: MeshFormat) -> None:
    """Make `fmt` the format of each of its suffixes (ValueError for a suffix taken)."""
    for suffix in fmt.suffixes:
        if suffix != suffix.lower() or not suffix.startswith("."):
            raise ValueError(f"a format's suffixes are lower case with a dot; got {suffix!r}.")
        if suffix in _FORMATS and _FORMATS[suffix] is not fmt:
            raise ValueError(f"{suffix} is the suffix of {_FORMATS[suffix].name} already.")
        _FORMATS[suffix] = fmt


def mesh_formats() -> list[MeshFormat]:
    """Every registered format once, in the order users see them."""
    return list(dict.fromkeys(_FORMATS.values()))


def mesh_format(path, *, action: str = "write") -> MeshFormat:
    """The format the suffix of `path` names.

    Raises
    ------
    UnknownSuffixError
        A suffix no format has (the message lists those that do).

    Examples
    --------
    >>> mesh_format("out/brain.ELE").name
    'triangle/tetgen'
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _FORMATS:
        verb = {"write": "write a mesh as", "read": "read a mesh from"}.get(action, action)
        what = suffix or ("(none)" if action == "write" else "")
        raise UnknownSuffixError(
            f"cannot {verb} {p.name!r}: unknown suffix {what!r}; use one of "
            f"{', '.join(_FORMATS)}.")
    return _FORMATS[suffix]


# ----------------------------------------------------------------------------- file names

_FACETS_STEM = "_facets"
#: Triangle's and TetGen's boundary-marker file, by dimension.
FACET_SUFFIX = {2: ".poly", 3: ".face"}


def facets_companion(path) -> Path:
    """The facets file beside mesh file `path`: ``<stem>_facets.vtu`` for a ``.vtu``,
    ``<stem>_<format>_facets.vtu`` for any other format (the two never collide).

    Examples
    --------
    >>> facets_companion("out/brain.vtu").as_posix()
    'out/brain_facets.vtu'
    >>> facets_companion("out/brain.xdmf").as_posix()
    'out/brain_xdmf_facets.vtu'
    """
    p = Path(path)
    kind = p.suffix.lower().lstrip(".")
    middle = "" if kind == VTU.suffix.lstrip(".") else f"_{kind}"
    return p.with_name(f"{p.stem}{middle}{_FACETS_STEM}{VTU.suffix}")


def is_facets_file(path) -> bool:
    """Whether `path` is named as a facets companion (``*_facets.vtu``)."""
    return Path(path).name.lower().endswith(_FACETS_STEM + VTU.suffix)


def node_ele_pair(path) -> tuple[Path, Path]:
    """The ``.node`` and ``.ele`` files of a Triangle/TetGen mesh named by either."""
    p = Path(path)
    return p.with_suffix(NODE_ELE.suffixes[0]), p.with_suffix(NODE_ELE.suffixes[1])


# ----------------------------------------------------------------------------- writers
# Each takes the prepared mesh (``_prepare.ExportMesh``) and the temporary paths of the
# targets, in the order of ``MeshFormat.targets``; imports are local (cost and cycles).


def _write_vtu(ex, temps, **_):
    from ._facet_vtu import write_facets_vtu
    from ._vtu import write_vtu

    write_vtu(temps[0], ex.points, ex.cell_blocks(),
              cell_data={"material": ex.material, **ex.mesh.cell_data})
    if temps[1:]:
        write_facets_vtu(ex, temps[1])


def _write_vtk(ex, temps, **_):
    from ._legacy_vtk import write_legacy_vtk

    write_legacy_vtk(ex, temps[0])


def _write_gmsh(ex, temps, *, binary=True, **_):
    from ._gmsh import write_gmsh

    write_gmsh(ex, temps[0], binary=binary)


def _write_xdmf(ex, temps, **_):
    from ._facet_vtu import write_facets_vtu
    from ._xdmf import write_xdmf_blocks

    write_xdmf_blocks(ex, temps[0], temps[1])
    if temps[2:]:
        write_facets_vtu(ex, temps[2])


def _write_abaqus(ex, temps, *, abaqus_elements="mechanical", **_):
    from ._abaqus import write_abaqus

    write_abaqus(ex, temps[0], elements=abaqus_elements)


def _write_node_ele(ex, temps, **_):
    from ._triangle_tetgen import write_facet_markers, write_node_ele

    write_node_ele(ex, temps[0], temps[1])
    if temps[2:]:
        write_facet_markers(ex, temps[2])


# ----------------------------------------------------------------------------- readers


def _meshio_reader(name: str):
    def read(path):
        from ._meshio_read import read_with_meshio

        return read_with_meshio(path, name)
    return read


def _read_node_ele(path):
    from ._triangle_tetgen import read_node_ele

    points, cells, attributes = read_node_ele(node_ele_pair(path))
    material = attributes.pop("material", None)
    return points, cells, material, attributes, {}


def _require_h5py(action: str) -> None:
    from ._xdmf import require_h5py

    require_h5py(action)


def _check_gmsh_labels(labels, exclude) -> None:
    from ._gmsh import check_gmsh_labels

    check_gmsh_labels(labels, exclude)


# ----------------------------------------------------------------------------- the table

VTU = MeshFormat(
    "vtu", (".vtu",), "VTK XML unstructured grid (+ <stem>_facets.vtu)",
    files=lambda p: [p], write=_write_vtu, read=_meshio_reader("vtu"),
    companion=lambda main, ndim: facets_companion(main), fields=True)
VTK = MeshFormat(
    "vtk", (".vtk",), "legacy VTK", files=lambda p: [p], write=_write_vtk,
    read=_meshio_reader("vtk"), facet_groups=False, label="legacy .vtk")
GMSH = MeshFormat(
    "gmsh", (".msh",), "Gmsh 4.1 with physical groups", files=lambda p: [p],
    write=_write_gmsh, read=_meshio_reader("gmsh"), options=frozenset({"binary"}),
    check_labels=_check_gmsh_labels)
XDMF = MeshFormat(
    "xdmf", (".xdmf",), "XDMF with its HDF5 .h5 file (+ <stem>_xdmf_facets.vtu)",
    files=lambda p: [p, p.with_suffix(".h5")], write=_write_xdmf,
    read=_meshio_reader("xdmf"), companion=lambda main, ndim: facets_companion(main),
    requires=_require_h5py, fields=True, series=True)
ABAQUS = MeshFormat(
    "abaqus", (".inp",), "Abaqus with element sets and facet surfaces", files=lambda p: [p],
    write=_write_abaqus, read=_meshio_reader("abaqus"),
    options=frozenset({"abaqus_elements"}))
NODE_ELE = MeshFormat(
    "triangle/tetgen", (".node", ".ele"),
    "Triangle (2-D) / TetGen (3-D) .node + .ele (+ .poly / .face)",
    files=lambda p: list(node_ele_pair(p)), write=_write_node_ele, read=_read_node_ele,
    companion=lambda main, ndim: (main.with_suffix(FACET_SUFFIX[ndim])
                                  if ndim in FACET_SUFFIX else None))

for _fmt in (VTU, VTK, GMSH, XDMF, ABAQUS, NODE_ELE):
    register_format(_fmt)
del _fmt

#: Suffix -> short description, in the order shown to users (every suffix, .ele too).
MESH_SUFFIXES = {suffix: fmt.description for suffix, fmt in _FORMATS.items()}

#: Partitioned (block-wise, issue 27) outputs: the index file's suffix -> its pieces'
#: suffix (``mesh.blocks`` writes them; ``.pvtu`` is read by ``read_mesh``, which joins
#: the pieces). Kept here so the registry stays the one place that knows suffixes.
PARTITIONED = {".pvtu": ".vtu", ".xdmf": ".h5"}
PVTU = ".pvtu"
XDMF_INDEX = ".xdmf"
