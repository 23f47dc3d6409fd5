"""How a mesh was made: the typed record the mesher leaves on :class:`~._types.Mesh`.

``Mesh.recipe`` says how the template or Delaunay mesher made a mesh (method, excluded
materials, lattice, size cap, periodic faces, coarsening, adaptive steps), so that the
tools that mesh the labels again (adaptive refinement, a remesh at another refine level,
the napari tabs) read declared fields instead of decoding ``Mesh.info``, which holds counts
and timings only. ``Mesh.made`` is the mesher's cache for the facet groups' pass
(:class:`MadeLattice`).

Neither is trusted behind a fingerprint: both are fields of the mesh, cleared when its
points, cells, materials, per-element data, spacing or shape are assigned anew (and absent
from a copy made with ``dataclasses.replace``, or from any mesh built from arrays), carried
only where a function says so (:meth:`Mesh.with_material_names`, the mesher itself). The
arrays :class:`MadeLattice` vouches for are read-only, and it holds them, so it applies
exactly while the mesh holds the same array objects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesher._lattice import Lattice

__all__ = ["Adapted", "MadeLattice", "Recipe"]


@dataclass(frozen=True)
class Adapted:
    """The adaptive steps behind a mesh (:func:`~._adapt.refine_marked`).

    Attributes
    ----------
    steps : int
        Refinement steps since the labels' own mesh (1 after the first).
    marked_elements : int
        Elements marked in the last step.
    split_leaves : int
        Leaves cut into 2^d in the last step.
    from_refine : int
        Refine level of the lattice the first (unadapted) mesh was made on.
    """

    steps: int
    marked_elements: int
    split_leaves: int
    from_refine: int

    def to_dict(self) -> dict:
        """Plain data for reports and ``--json``."""
        return {"steps": self.steps, "marked_elements": self.marked_elements,
                "split_leaves": self.split_leaves, "from_refine": self.from_refine}


@dataclass(frozen=True)
class Recipe:
    """How the mesher made a mesh: what meshing its labels again needs.

    Attributes
    ----------
    method : {"template", "delaunay"}
        The mesher's method.
    exclude : tuple of int
        Materials left out of the mesh, sorted.
    balance : str
        The tree balance used: ``"faces"``, ``"faces+edges"`` or ``"faces+edges+corners"``.
    lattice : Lattice or None
        The lattice the voxels were cut into (spacing, subdivision factors, refine level,
        max aspect); None for a mesh of a tree (:func:`~._imesh.mesh_tree`), whose cells
        are the tree's own.
    max_size : float or None
        The longest element edge asked for.
    periodic : bool
        Opposite faces of the image box have the same vertices and facets.
    coarsen : int
        Level of the label coarsening before meshing (blocks of ``2**coarsen`` voxels;
        the volume changes are counted in ``info["coarsen"]``); 0: none.
    diagonal_rule : str or None
        How the 3-D templates cut a plain leaf: ``"parity"``, or ``"lowest"`` (Kuhn's) in
        a periodic mesh of odd extent and in 2-D; None for the Delaunay method.
    adapted : Adapted or None
        The adaptive refinement steps that made the mesh; None for the labels' own mesh.
    """

    method: str
    exclude: tuple[int, ...] = ()
    balance: str = "faces+edges"
    lattice: Lattice | None = None
    max_size: float | None = None
    periodic: bool = False
    coarsen: int = 0
    diagonal_rule: str | None = None
    adapted: Adapted | None = None

    @property
    def refine(self) -> int:
        """The lattice's interface refinement level (0 without a lattice)."""
        return 0 if self.lattice is None else int(self.lattice.refine)

    @property
    def subdivided(self) -> bool:
        """Whether anisotropic voxels were cut into more than one lattice cell."""
        return self.lattice is not None and any(int(f) > 1 for f in self.lattice.factors)

    @property
    def remeshable(self) -> bool:
        """Whether the labels can be meshed again as this mesh was: a template mesh of a
        label image on its lattice, not coarsened."""
        return self.method == "template" and self.lattice is not None and not self.coarsen


@dataclass(frozen=True)
class MadeLattice:
    """What the template mesher knows of a mesh it made, kept on it as ``Mesh.made``.

    It holds the read-only arrays it vouches for (points, cells and the ``leaf`` and
    ``level`` of every element) and applies while the mesh holds those very arrays
    (:meth:`applies_to`): then the facet groups' pass takes from here what it would
    otherwise recompute from the points: every element is positive (the templates are
    cut that way), so no sign pass over all elements; the lattice points packed; and the
    lattice origin of every leaf.
    """

    points: np.ndarray
    cells: np.ndarray
    leaf: np.ndarray
    level: np.ndarray
    packed: tuple[np.ndarray, int] | None   # as :func:`~._packed.pack_points` gives
    leaf_origin: np.ndarray                 # (leaves of the balanced tree, d) lattice cells

    @classmethod
    def record(cls, mesh, packed, leaf_origin: np.ndarray) -> MadeLattice:
        """The record of `mesh` as the mesher made it; its arrays become read-only."""
        small = leaf_origin.size == 0 or int(leaf_origin.max()) < 2**31
        held = (mesh.points, mesh.cells, mesh.cell_data["leaf"], mesh.cell_data["level"])
        for array in held:
            array.flags.writeable = False
        return cls(*held, packed, leaf_origin.astype(np.int32) if small else leaf_origin)

    def applies_to(self, mesh) -> bool:
        """Whether `mesh` still holds the arrays this record was made for."""
        cd = mesh.cell_data
        return (mesh.points is self.points and mesh.cells is self.cells
                and cd.get("leaf") is self.leaf and cd.get("level") is self.level)
