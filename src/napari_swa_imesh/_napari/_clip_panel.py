"""Clip controls of the mesh tab: a plane across one axis that keeps whole elements.

Only the controls live here; what is kept and drawn is :class:`~napari_swa_imesh.mesh.MeshClipper`
(plain numpy, tested without Qt). A slider emits many values a second while napari needs
a good part of a second (software OpenGL) to upload and draw a new surface, so changes are
throttled: the first change starts a short timer, further ones only update the wanted
position, and when the timer fires the surface is drawn once for the latest one. The
event loop runs in between, so the slider never freezes.
"""

from __future__ import annotations

from collections.abc import Callable

from magicgui.widgets import CheckBox, ComboBox, Container, FloatSlider
from qtpy.QtCore import QTimer

from ..mesh import MeshClipper
from ._dock import Fold, wrapped_label

__all__ = ["ClipPanel", "AXIS_CHOICES", "KEEP_CHOICES", "THROTTLE_MS"]

#: Axis names as napari shows them, by mesh dimension: (text, axis of the points).
AXIS_CHOICES = {3: [("z (planes)", 0), ("y (rows)", 1), ("x (columns)", 2)],
                2: [("y (rows)", 0), ("x (columns)", 1)]}
KEEP_CHOICES = [("below the plane", "below"), ("above the plane", "above")]
THROTTLE_MS = 40
_STEPS = 400            # slider positions across the mesh


class ClipPanel:
    """Enable box, axis, side and position of the clipping plane, with a count of what shows.

    Parameters
    ----------
    on_change : callable
        Called (throttled, without arguments) whenever the clip to show has changed.
    """

    def __init__(self, on_change: Callable[[], None]):
        self.clipper: MeshClipper | None = None
        self._on_change = on_change
        self.enable_box = CheckBox(
            text="clip: keep the whole elements on one side of a plane", value=False,
            tooltip="Show the tetrahedra inside the mesh: every element with a vertex on "
                    "the kept side stays whole (as 3-D Slicer's 'keep whole cells'), and "
                    "the surface of that set is drawn.")
        self.axis_combo = ComboBox(label="axis", choices=AXIS_CHOICES[3])
        self.keep_combo = ComboBox(label="keep", choices=KEEP_CHOICES)
        self.position_slider = FloatSlider(label="position", min=0.0, max=1.0, step=1e-3,
                                           value=0.5, tracking=True,
                                           tooltip="Where the plane crosses the axis, in "
                                                   "the mesh's physical units.")
        self.status = wrapped_label()
        self.timer = QTimer()
        self.timer.setSingleShot(True)
        self.timer.setInterval(THROTTLE_MS)
        self.timer.timeout.connect(self._fire)
        self.enable_box.changed.connect(self._changed)
        self.keep_combo.changed.connect(self._changed)
        self.position_slider.changed.connect(self._changed)
        self.axis_combo.changed.connect(self._axis_changed)
        self.set_clipper(None)

    def widget(self) -> Fold:
        """The controls in a section that folds away (folded to start with)."""
        controls = Container(widgets=[self.axis_combo, self.keep_combo, self.position_slider])
        box = Fold("see inside", [self.enable_box, controls, self.status.native])
        # the throttle timer dies with the controls: it never fires into a deleted widget
        self.timer.setParent(box)
        return box

    # -- state -----------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        """Whether the view should be clipped (enabled, with a mesh to clip)."""
        return self.clipper is not None and bool(self.enable_box.value)

    def settings(self) -> tuple[int, float, str]:
        """(axis, position, keep) for :meth:`MeshClipper.surface`."""
        return (int(self.axis_combo.value), float(self.position_slider.value),
                str(self.keep_combo.value))

    def set_clipper(self, clipper: MeshClipper | None) -> None:
        """Clip this mesh next (None: nothing to clip); the plane keeps its axis if it can."""
        self.clipper = clipper
        for w in (self.enable_box, self.axis_combo, self.keep_combo, self.position_slider):
            w.enabled = clipper is not None
        if clipper is None:
            self.status.value = "mesh a Labels layer to clip it"
            return
        choices = AXIS_CHOICES[clipper.mesh.ndim]
        axis = self.axis_combo.value
        with self.axis_combo.changed.blocked():
            self.axis_combo.choices = choices
            if axis in [a for _, a in choices]:
                self.axis_combo.value = axis
        self._fit_slider(middle=True)

    def _fit_slider(self, *, middle: bool) -> None:
        """Slider range: the mesh's extent on the axis (position in the middle, or kept)."""
        lo, hi = self.clipper.extent(int(self.axis_combo.value))
        old = float(self.position_slider.value)
        with self.position_slider.changed.blocked():
            # the new range first, wide enough for the old value, so magicgui never clamps
            self.position_slider.min = min(lo, old)
            self.position_slider.max = max(hi, old, lo + 1e-9)
            self.position_slider.step = max(hi - lo, 1e-9) / _STEPS
            value = (lo + hi) / 2 if middle or not lo <= old <= hi else old
            self.position_slider.value = value
            self.position_slider.min, self.position_slider.max = lo, max(hi, lo + 1e-9)

    # -- events ----------------------------------------------------------------------------
    def _axis_changed(self, *_) -> None:
        if self.clipper is not None:
            self._fit_slider(middle=True)
        self._changed()

    def _changed(self, *_) -> None:
        if not self.timer.isActive():
            self.timer.start()

    def _fire(self) -> None:
        self._on_change()

    def show_counts(self, surface: dict | None) -> None:
        """Say what the view shows: the kept elements and faces, or the whole mesh."""
        if self.clipper is None:
            return
        n = self.clipper.mesh.n_cells
        if surface is None or not self.active:
            self.status.value = f"not clipped: all {n} elements"
        else:
            self.status.value = (f"{surface['n_kept']} of {n} elements kept whole; "
                                 f"{surface['n_faces']} faces drawn")
