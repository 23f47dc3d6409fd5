"""Dock layout shared by the widgets: content that scrolls instead of growing the window.

A dock's minimum height adds to napari's window: five docks whose content cannot shrink
grew the window past the screen (2363 px on a 1024-px screen) and napari kept that size at
the next start. Every widget of the plugin therefore lays its content out in a scroll area
(:func:`scroll_body`): the dock can be as short as the user makes it, and plots get a modest
minimum height and grow with the space they are given.
"""

from __future__ import annotations

from qtpy.QtWidgets import QFrame, QGroupBox, QScrollArea, QSizePolicy, QVBoxLayout, QWidget

__all__ = ["scroll_body", "side_by_side", "group", "wrapped_label", "button",
           "SCROLL_MIN_HEIGHT"]

SCROLL_MIN_HEIGHT = 48


def scroll_body(widget: QWidget) -> QVBoxLayout:
    """Give `widget` a scroll area around a body widget; return the body's layout."""
    body = QWidget()
    area = QScrollArea()
    area.setWidget(body)
    area.setWidgetResizable(True)
    area.setFrameShape(QFrame.NoFrame)
    # below Qt's own minimum (about 90 px with its scroll bars): six docks of the plugin
    # stacked in one dock area must still fit a small screen
    area.setMinimumHeight(SCROLL_MIN_HEIGHT)
    outer = QVBoxLayout(widget)
    outer.setContentsMargins(0, 0, 0, 0)
    outer.addWidget(area)
    return QVBoxLayout(body)


def side_by_side(*widgets) -> QWidget:
    """magicgui widgets side by side, without labels."""
    from magicgui.widgets import Container

    return Container(widgets=list(widgets), layout="horizontal", labels=False).native


def group(title: str, widgets) -> QGroupBox:
    """A titled box around widgets (magicgui or Qt), one under the other."""
    box = QGroupBox(title)
    layout = QVBoxLayout(box)
    for widget in widgets:
        layout.addWidget(getattr(widget, "native", widget))
    return box


def wrapped_label(text: str = ""):
    """A magicgui Label whose text wraps to the dock's width.

    Add its ``.native`` to a layout directly: magicgui sizes labels (and the rows of a
    labelled Container) to their unwrapped text, which would widen the dock.
    """
    from magicgui.widgets import Label

    label = Label(value=text)
    label.native.setWordWrap(True)
    label.native.setSizePolicy(QSizePolicy.Preferred, QSizePolicy.Preferred)
    return label


def button(text: str, slot, tooltip: str | None = None):
    """A magicgui PushButton that calls ``slot()`` when clicked."""
    from magicgui.widgets import PushButton

    widget = PushButton(text=text, tooltip=tooltip)
    widget.changed.connect(lambda *_: slot())
    return widget
