"""The mesh container shared by the mesher, the quality metrics, the checks and the writers.

Conventions
-----------
* ``points`` are physical coordinates in numpy/napari axis order (plane, row, column),
  i.e. pixel corner index times spacing. The image box is ``[0, shape[a]*spacing[a]]``.
* ``cells`` index ``points``; every cell has positive signed volume in these coordinates:
  ``det([p1-p0, p2-p0(, p3-p0)]) > 0`` with columns in axis order.
* ``world`` says where the points go in a file: None, the axes reversed to x, y(, z) =
  column, row(, plane), the order FE tools expect; or a homogeneous matrix from ``points``
  to x, y(, z) (a NIfTI affine, :func:`world_from_affine`). The writers call
  ``_common.export_points`` for it and reorder each cell so its volume stays positive
  there. Everything else (checks, facet groups, quality, simulation) works on ``points``.
* ``recipe`` and ``made`` (:mod:`._recipe`) say how the mesher made the mesh; assigning
  the arrays, the spacing or the shape anew clears both, and a mesh built from arrays or
  copied by ``dataclasses.replace`` has neither (carry them with a method that says so).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ._recipe import MadeLattice, Recipe

__all__ = ["Mesh"]

#: fields a recipe describes: assigning one anew makes the mesh another mesh
_MADE_OF = frozenset({"points", "cells", "material", "cell_data", "spacing", "shape"})


@dataclass
class Mesh:
    """A simplicial mesh with one material per element.

    Built from arrays, a mesh checks and normalises them once (O(N + M), no copy when the
    dtypes already match), so every function that takes a ``Mesh`` can trust it.

    Attributes
    ----------
    points : (N, d) ndarray of float64
        Vertex coordinates, physical units, axis order of the image; finite.
    cells : (M, d+1) ndarray of intp
        Triangles (d=2) or tetrahedra (d=3), positively oriented; every id in ``0..N-1``.
    material : (M,) ndarray of int64
        Label of the leaf each element lies in.
    cell_data : dict of str to (M,) ndarray
        Per-element data: at least ``quality`` (radius-to-edge ratio) and ``level`` (leaf
        level); the mesher adds angle metrics.
    spacing : tuple of float
        Voxel spacing used to place the points (empty when unknown).
    shape : tuple of int
        Shape of the label image that was meshed (empty when unknown).
    material_names : dict of int to str
        Optional names for material ids (used by Gmsh physical groups and Abaqus sets).
    info : dict
        Counts and timings of the run that made the mesh (for reports and ``--json``).
    recipe : Recipe or None
        How the mesher made the mesh (method, exclusions, lattice, size cap, periodic
        faces, coarsening, adaptive steps); None for a mesh built from arrays, read from
        a file, copied with ``dataclasses.replace`` or changed since (an array, the
        spacing or the shape assigned anew). Not a constructor argument.
    made : MadeLattice or None
        The template mesher's cache for the facet groups (its arrays are read-only);
        None as `recipe` is.
    world : (d+1, d+1) ndarray of float64 or None
        Homogeneous map from `points` to the coordinates files get (x, y(, z)); its
        last row is ``[0, .., 0, 1]`` and its linear part invertible. None: the axes
        reversed (column, row(, plane)).

    Raises
    ------
    TypeError
        For non-numeric points or non-integer cells or materials.
    ValueError
        For arrays of the wrong shape, non-finite points, cell ids out of range,
        per-cell arrays whose length is not the number of cells, or a `world` matrix
        that is not an invertible affine map of the points' dimension.

    Examples
    --------
    >>> m = Mesh([[0, 0], [0, 1], [1, 0]], [[0, 2, 1]], [1])
    >>> m.points.dtype, m.cells.dtype == np.intp, m.n_cells
    (dtype('float64'), True, 1)
    """

    points: np.ndarray
    cells: np.ndarray
    material: np.ndarray
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)
    spacing: tuple[float, ...] = ()
    shape: tuple[int, ...] = ()
    material_names: dict[int, str] = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    world: np.ndarray | None = None
    recipe: Recipe | None = field(default=None, init=False, compare=False)
    made: MadeLattice | None = field(default=None, init=False, repr=False, compare=False)

    def __setattr__(self, name, value):
        # after construction, a new array, spacing or shape is another mesh: what the
        # mesher recorded of this one no longer holds
        if name in _MADE_OF and "made" in self.__dict__:
            object.__setattr__(self, "recipe", None)
            object.__setattr__(self, "made", None)
        object.__setattr__(self, name, value)

    def __post_init__(self):
        self.points = _as_points(self.points)
        d = self.points.shape[1]
        self.cells = _as_cells(self.cells, d, len(self.points))
        m = len(self.cells)
        self.material = _as_ids(self.material, "material", m)
        self.cell_data = {str(k): _per_cell(v, f"cell_data[{k!r}]", m)
                          for k, v in dict(self.cell_data or {}).items()}
        self.spacing = tuple(float(s) for s in self.spacing)
        self.shape = tuple(int(n) for n in self.shape)
        for name, value in (("spacing", self.spacing), ("shape", self.shape)):
            if len(value) not in (0, d):
                raise ValueError(f"{name} must be empty or hold {d} values (one per axis); "
                                 f"got {value}.")
        self.material_names = {int(k): str(v) for k, v in dict(self.material_names or {}).items()}
        self.info = dict(self.info or {})
        self.world = None if self.world is None else _as_world(self.world, d)

    @classmethod
    def _trusted(cls, points, cells, material, cell_data, *, spacing, shape,
                 material_names, info, world=None) -> Mesh:
        """A mesh from arrays the mesher made (already of the right dtypes and shapes)."""
        mesh = cls.__new__(cls)
        mesh.points, mesh.cells, mesh.material, mesh.cell_data = points, cells, material, cell_data
        mesh.spacing, mesh.shape = spacing, shape
        mesh.material_names, mesh.info, mesh.world = material_names, info, world
        mesh.recipe = mesh.made = None
        return mesh

    def with_material_names(self, names: dict[int, str]) -> Mesh:
        """The same mesh (the same arrays, recipe and record) with other material names.

        Examples
        --------
        >>> m = Mesh([[0, 0], [0, 1], [1, 0]], [[0, 2, 1]], [1])
        >>> m.with_material_names({1: "pore"}).material_names
        {1: 'pore'}
        """
        out = copy.copy(self)
        # the same arrays: the recipe and the record still hold (the dicts are the copy's)
        object.__setattr__(out, "cell_data", dict(self.cell_data))
        out.info = dict(self.info)
        out.material_names = {int(k): str(v) for k, v in dict(names or {}).items()}
        return out

    @property
    def ndim(self) -> int:
        return int(self.points.shape[1])

    @property
    def n_cells(self) -> int:
        return int(self.cells.shape[0])

    @property
    def quality(self) -> np.ndarray:
        """(M,) radius-to-edge ratio of each element."""
        return self.cell_data["quality"]

    @property
    def records_box(self) -> bool:
        """Whether the mesh knows the image it was made from (`shape` and `spacing`)."""
        return len(self.shape) == self.ndim and len(self.spacing) == self.ndim

    def image_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corner of the image box, in the points' axis order.

        ``[0, shape * spacing]`` when the mesh records its image, so that materials left
        out of the mesh on a face do not shrink the box; else the extent of the points
        (a mesh read from a file).
        """
        if self.records_box:
            return (np.zeros(self.ndim),
                    np.asarray(self.shape, dtype=np.float64) * np.asarray(self.spacing, float))
        return self.points.min(axis=0), self.points.max(axis=0)

    def to_pyvista(self):
        """The mesh as a ``pyvista.UnstructuredGrid``, for VTK's filters and plotting.

        Points in the exported frame (x, y(, z), as the mesh files have them; 2-D meshes
        on the plane z = 0), cells ``VTK_TRIANGLE`` or ``VTK_TETRA`` positively oriented
        there, cell data ``material`` and every array of ``cell_data``. Cell ``i`` of the
        grid is element ``i``, point ``j`` is vertex ``j``; the filters that pass
        ``vtkOriginalPointIds`` (``extract_cells``, ``extract_surface``) lead back to
        ``points``, the (plane, row, column) coordinates napari draws. Needs pyvista
        (imported here, not with the package).

        Returns
        -------
        pyvista.UnstructuredGrid

        Raises
        ------
        ImportError
            Without pyvista.

        Examples
        --------
        >>> m = Mesh([[0, 0], [0, 1], [1, 0]], [[0, 2, 1]], [7])
        >>> grid = m.to_pyvista()
        >>> grid.n_cells, grid.cell_data["material"].tolist()
        (1, [7])
        """
        from ..formats._pyvista import to_pyvista

        return to_pyvista(self)


def _as_points(points) -> np.ndarray:
    arr = np.asarray(points)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"mesh points must be real numbers; got dtype {arr.dtype}.")
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ValueError(f"mesh points must have shape (N, 2) or (N, 3); got {arr.shape}.")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        bad = int(np.count_nonzero(~np.isfinite(arr).all(axis=1)))
        raise ValueError(f"{bad} mesh point(s) have NaN or infinite coordinates; every "
                         "vertex needs a finite position.")
    return arr


def _as_world(world, d: int) -> np.ndarray:
    arr = np.asarray(world)
    if arr.dtype.kind not in "biuf" or arr.shape != (d + 1, d + 1):
        raise ValueError(f"world must be a ({d + 1}, {d + 1}) matrix of numbers for a {d}-D "
                         f"mesh; got {arr.dtype} of shape {arr.shape}.")
    arr = np.array(arr, dtype=np.float64)
    last = np.zeros(d + 1)
    last[d] = 1.0
    if not np.isfinite(arr).all() or not np.array_equal(arr[d], last):
        raise ValueError(f"world must be finite with last row {last.tolist()} (an affine "
                         f"map); got {arr.tolist()}.")
    sv = np.linalg.svd(arr[:d, :d], compute_uv=False)
    if not sv[-1] > 1e-12 * sv[0]:
        raise ValueError(f"world's linear part {arr[:d, :d].tolist()} is singular; points "
                         "would collapse. Give an invertible map.")
    return arr


def _as_cells(cells, d: int, n_points: int) -> np.ndarray:
    arr = np.asarray(cells)
    if arr.size == 0 and arr.ndim < 2:
        arr = arr.reshape(0, d + 1)
    if arr.dtype.kind not in "iu" and arr.size:
        raise TypeError(f"cells must hold integer vertex ids; got dtype {arr.dtype}.")
    if arr.ndim != 2 or arr.shape[1] != d + 1:
        raise ValueError(f"cells of a {d}-D mesh need {d + 1} corners each; got shape "
                         f"{arr.shape}.")
    if arr.size:
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0 or hi >= n_points:
            raise ValueError(f"cells refer to vertices {lo}..{hi}, but the mesh has "
                             f"{n_points} points (ids 0..{n_points - 1}).")
    return np.asarray(arr, dtype=np.intp)


def _as_ids(values, name: str, m: int) -> np.ndarray:
    arr = _per_cell(values, name, m)
    if arr.dtype.kind not in "iub" and arr.size:
        raise TypeError(f"{name} must hold integer ids; got dtype {arr.dtype}.")
    if arr.ndim != 1:
        raise ValueError(f"{name} must hold one id per element ({m}); got shape {arr.shape}.")
    return np.asarray(arr, dtype=np.int64)


def _per_cell(values, name: str, m: int) -> np.ndarray:
    arr = np.asarray(values)
    if arr.shape[:1] != (m,):
        what = "id" if name == "material" else "value"
        raise ValueError(f"{name} must hold one {what} per element ({m}); got shape {arr.shape}.")
    return arr
