"""See inside a mesh: keep the whole elements on one side of an axis-aligned plane.

Pure numpy, like :mod:`._surface`: the widget package adapts the result to a napari layer.

The clip keeps whole cells, as 3-D Slicer's Segment Mesher does and as VTK's "crinkle"
clip (``pyvista.DataSet.clip(..., crinkle=True)``) does: every element with at least one
vertex strictly on the kept side, the elements the plane cuts included. The surface of
that set is drawn, so the tetrahedra at the cut show their faces instead of a flat slice.

A slider moves the plane many times a second, so the work per move avoids pairing the
faces of the whole mesh again. The kept set's boundary is

* the mesh's own boundary faces with a vertex on the kept side (found once by
  :func:`._surface.shown_faces`, masked per move; their element has that vertex too), and
* among the faces of kept elements with *no* vertex on the kept side (only cut elements
  have them: a thin band along the plane), those met once: a face met twice lies between
  two kept elements.

A face of a kept element with a vertex on the kept side is shared only with an element
that has that vertex, hence kept: such a face is on the boundary only where the mesh
itself ends, which the first item covers.
"""

from __future__ import annotations

import numpy as np

from ._facets import FACE_CORNERS
from ._surface import per_triangle_surface, shown_faces

__all__ = ["KEEP_SIDES", "clip_cells", "MeshClipper"]

#: Which side of the plane is kept: coordinates below or above the position.
KEEP_SIDES = ("below", "above")


def _check_keep(keep: str) -> bool:
    """True for "above"; ValueError for anything but the two sides."""
    if keep not in KEEP_SIDES:
        raise ValueError(f"keep must be one of {KEEP_SIDES}; got {keep!r}.")
    return keep == "above"


def _check_axis(axis, d: int) -> int:
    if not isinstance(axis, (int, np.integer)) or isinstance(axis, bool) or not 0 <= axis < d:
        raise ValueError(f"axis must be an integer from 0 to {d - 1} (plane, row(, column) "
                         f"order of a {d}-D mesh); got {axis!r}.")
    return int(axis)


def _on_side(values: np.ndarray, position: float, above: bool) -> np.ndarray:
    """Strictly on the kept side: a vertex on the plane belongs to neither side."""
    return values > position if above else values < position


def clip_cells(points: np.ndarray, cells: np.ndarray, axis: int, position: float, *,
               keep: str = "below") -> np.ndarray:
    """Which elements a "keep whole cells" clip keeps: those with a vertex on the kept side.

    Parameters
    ----------
    points : (N, d) ndarray of float
    cells : (M, d+1) ndarray of int
    axis : int
        Axis of the plane's normal, in the points' (plane, row(, column)) order.
    position : float
        Where the plane crosses `axis`, in the points' units.
    keep : {"below", "above"}
        Keep the elements with a vertex at a coordinate below (or above) `position`.

    Returns
    -------
    (M,) ndarray of bool

    Examples
    --------
    >>> pts = np.array([[0., 0.], [0., 1.], [1., 0.], [1., 1.], [2., 0.]])
    >>> clip_cells(pts, np.array([[0, 2, 1], [2, 3, 1], [2, 4, 3]]), 0, 0.5).tolist()
    [True, True, False]
    """
    points = np.asarray(points, dtype=np.float64)
    axis = _check_axis(axis, points.shape[1])
    above = _check_keep(keep)
    return np.asarray(_on_side(points[:, axis][cells], float(position), above).any(axis=1))


class MeshClipper:
    """The surface of a mesh clipped by an axis-aligned plane, fast enough for a slider.

    Holds what does not change while the plane moves: the mesh's boundary faces and the
    extent of every element along the axes asked for (about 16 bytes per element and
    axis). Each :meth:`surface` call is then a few masks over the elements and a sort of
    the faces of the elements the plane cuts.

    Parameters
    ----------
    mesh : Mesh
        Triangles or tetrahedra with ``quality`` in ``cell_data``.
    shown : tuple of ndarray, optional
        ``shown_faces(mesh.cells, mesh.material)`` when already computed (the unclipped
        view needs it too), to skip pairing the faces a second time.

    Examples
    --------
    >>> from napari_swa_imesh.mesh import mesh_labels
    >>> mesh = mesh_labels(np.arange(8).reshape(2, 2, 2) % 2 + 1)   # 8 cubes, 5 tets each
    >>> clipper = MeshClipper(mesh)
    >>> clipper.surface(0, 2.0)["n_faces"]      # all kept: 6 sides of 4 squares, 2 triangles
    48
    >>> cut = clipper.surface(0, 0.5)           # the lower layer of cubes: a 2 x 2 x 1 slab
    >>> cut["n_kept"], cut["n_faces"]
    (20, 32)
    """

    def __init__(self, mesh, *, shown: tuple[np.ndarray, np.ndarray] | None = None):
        self.mesh = mesh
        self._cells = np.asarray(mesh.cells, dtype=np.intp)
        if mesh.ndim == 3:
            faces, owners = shown if shown is not None else shown_faces(self._cells,
                                                                       mesh.material)
            boundary = owners[:, 1] < 0
            self._boundary = faces[boundary]                   # (B, 3) outward
            self._boundary_owner = owners[boundary, 0]         # (B,)
        self._ranges: dict[int, tuple[np.ndarray, ...]] = {}

    def _axis_ranges(self, axis: int) -> tuple[np.ndarray, ...]:
        """Per element, then per boundary face: lowest and highest coordinate on `axis`."""
        if axis not in self._ranges:
            x = self.mesh.points[:, axis]
            corner = x[self._cells]                            # (M, d+1)
            out: tuple[np.ndarray, ...] = (corner.min(axis=1), corner.max(axis=1))
            if self.mesh.ndim == 3:
                face = x[self._boundary]                       # (B, 3)
                out += (face.min(axis=1), face.max(axis=1))
            self._ranges = {axis: out}                         # one axis at a time
        return self._ranges[axis]

    def extent(self, axis: int) -> tuple[float, float]:
        """Lowest and highest coordinate of the mesh on `axis` (the slider's range)."""
        axis = _check_axis(axis, self.mesh.ndim)
        x = self.mesh.points[:, axis]
        return (float(x.min()), float(x.max())) if len(x) else (0.0, 0.0)

    def kept(self, axis: int, position: float, *, keep: str = "below") -> np.ndarray:
        """(M,) bool: the elements kept (:func:`clip_cells`, from the cached extents)."""
        axis = _check_axis(axis, self.mesh.ndim)
        above = _check_keep(keep)
        lo, hi = self._axis_ranges(axis)[:2]
        return hi > position if above else lo < position

    def faces(self, axis: int, position: float, *, keep: str = "below"
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kept elements and the faces of their union.

        Returns
        -------
        kept : (M,) ndarray of bool
        faces : (F, 3) ndarray of intp
            3-D: the boundary of the kept set, each face once, oriented out of it;
            2-D: the kept triangles themselves.
        owner : (F,) ndarray of intp
            The kept element each face belongs to.
        """
        axis = _check_axis(axis, self.mesh.ndim)
        above = _check_keep(keep)
        kept = self.kept(axis, position, keep=keep)
        if self.mesh.ndim == 2:
            owner = np.flatnonzero(kept)
            return kept, self._cells[owner], owner
        lo, hi, face_lo, face_hi = self._axis_ranges(axis)
        x = self.mesh.points[:, axis]
        # mesh boundary faces with a vertex on the kept side (so their element is kept)
        outer = _on_side(face_hi if above else face_lo, position, above)
        # faces with no vertex on the kept side, of kept elements: only cut ones have them
        cut = np.flatnonzero(kept & ~_on_side(lo if above else hi, position, above))
        band = self._cells[cut][:, FACE_CORNERS[3]]            # (K, 4, 3) outward
        inner = ~_on_side(x[band], position, above).any(axis=2)  # (K, 4)
        band, band_owner = band[inner], np.broadcast_to(cut[:, None], inner.shape)[inner]
        key = np.sort(band, axis=1)                            # (C, 3) orientation-free
        order = np.lexsort(key.T[::-1])
        key = key[order]
        same = (key[1:] == key[:-1]).all(axis=1)               # (C-1,) pairs of one face
        once = np.ones(len(key), dtype=bool)
        once[1:] &= ~same
        once[:-1] &= ~same
        keep_rows = order[once]
        faces = np.concatenate([self._boundary[outer], band[keep_rows]])
        owner = np.concatenate([self._boundary_owner[outer], band_owner[keep_rows]])
        return kept, faces, owner

    def surface(self, axis: int, position: float, *, keep: str = "below"
                ) -> dict[str, np.ndarray | int]:
        """Everything a Surface layer needs to show the clipped mesh, in both colourings.

        Parameters
        ----------
        axis : int
            Axis of the plane's normal, (plane, row(, column)) order.
        position : float
            Where the plane crosses `axis`, in the mesh's units.
        keep : {"below", "above"}

        Returns
        -------
        dict
            As :func:`._surface.mesh_surface`: ``vertices (3F, d)``, ``triangles (F, 3)``,
            ``quality (3F,)`` and ``material (3F,)`` of the kept element each face
            bounds, ``n_faces``; and ``n_kept``, the number of elements kept.

        Raises
        ------
        ValueError
            For an axis outside the mesh's dimensions or a side other than "below" and
            "above".
        """
        kept, faces, owner = self.faces(axis, position, keep=keep)
        vertices, triangles, quality = per_triangle_surface(self.mesh.points, faces,
                                                            self.mesh.quality[owner])
        return {"vertices": vertices, "triangles": triangles, "quality": quality,
                "material": np.repeat(self.mesh.material[owner], 3),
                "n_faces": len(faces), "n_kept": int(np.count_nonzero(kept))}
