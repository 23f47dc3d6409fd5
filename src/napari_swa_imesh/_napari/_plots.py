"""Matplotlib figures in a dock: napari-matplotlib's themed canvas, sized to fit a screen.

:class:`ThemedFigure` is napari-matplotlib's ``BaseNapariMPLWidget`` (a canvas and toolbar
styled like the napari window, constrained layout) with what the plugin's plots need on
top: a draw callback run inside the theme's matplotlib style (again whenever the napari
theme changes), and a canvas with a modest minimum height that grows with the dock instead
of growing the window. The layer-selection callbacks of ``NapariMPLWidget`` are not used:
these plots follow their widget's own pickers, not the layer list's selection, and would
otherwise be redrawn on every slice step.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import matplotlib.style as mplstyle
from napari_matplotlib.base import BaseNapariMPLWidget
from qtpy.QtCore import QSize
from qtpy.QtWidgets import QSizePolicy

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    import napari

__all__ = ["ThemedFigure", "dark_theme", "theme_text_color"]


def dark_theme(viewer: napari.viewer.Viewer) -> bool:
    """True when the viewer's theme has a dark background."""
    from napari.utils.theme import get_theme

    _, _, lightness = get_theme(viewer.theme).background.as_hsl_tuple()
    return lightness <= 0.5


def theme_text_color(viewer: napari.viewer.Viewer) -> str:
    """Text colour (hex) of the viewer's theme."""
    from napari.utils.theme import get_theme

    return get_theme(viewer.theme).text.as_hex()


class ThemedFigure(BaseNapariMPLWidget):
    """A napari-themed matplotlib figure whose content `draw(figure)` draws.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
    draw : callable
        ``draw(figure)`` draws the whole figure (it clears it first); called by
        :meth:`redraw` and on every napari theme change, inside the theme's style.
    min_height : int
        Smallest canvas height in pixels; the canvas grows from there with its dock.
    """

    def __init__(self, viewer: napari.viewer.Viewer, draw: Callable[[Figure], None], *,
                 min_height: int):
        super().__init__(viewer)
        self._draw_figure = draw
        self.canvas.setMinimumHeight(min_height)
        self.canvas.setSizePolicy(QSizePolicy.Expanding, QSizePolicy.Expanding)
        self.layout().setContentsMargins(0, 0, 0, 0)

    def sizeHint(self) -> QSize:
        # ask for the minimum and grow with the dock: the scroll area lays its body out at
        # the preferred heights, and matplotlib's 480-px figure pushed results below a
        # laptop screen's fold
        hint = super().sizeHint()
        return QSize(hint.width(), self.minimumSizeHint().height())

    def redraw(self) -> None:
        """Draw the figure again in the current theme's style."""
        with mplstyle.context(self.napari_theme_style_sheet):
            self._draw_figure(self.figure)
        self.canvas.draw_idle()

    def _on_napari_theme_changed(self, event) -> None:
        # napari-matplotlib's hook (NapariMPLWidget overrides it the same way): the style
        # sheet is updated first, then the figure is drawn in it
        try:
            super()._on_napari_theme_changed(event)
            self.redraw()
        except RuntimeError:  # the Qt side is gone; napari drops us with the Python side
            pass
