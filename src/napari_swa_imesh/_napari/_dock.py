"""Dock layout shared by the widgets: content that scrolls instead of growing the window.

A dock's minimum height adds to napari's window: five docks whose content cannot shrink
grew the window past the screen (2363 px on a 1024-px screen) and napari kept that size at
the next start. Every widget of the plugin therefore lays its content out in a scroll area
(:func:`scroll_body`): the dock can be as short as the user makes it, and plots get a modest
minimum height and grow with the space they are given.

Width is kept for the canvas: on a 1280x800 laptop screen napari's layer panel takes about
300 px, and a 506-px dock left the canvas 235 px. The scroll area asks for at most
:data:`DOCK_WIDTH` px, :func:`fit_dock` lets combo boxes shrink below their longest choice
(the list still shows it whole), moves long check-box texts into wrapped labels and sizes
short tables to their rows, and :class:`Fold` hides sections a run does not need behind an
arrow. Heights matter as much: the body of a scroll area is laid out at its content's
preferred height, so plots ask for their minimum height (:mod:`._plots`) and grow from there.
"""

from __future__ import annotations

from qtpy.QtCore import QSize, Qt
from qtpy.QtWidgets import (
    QAbstractItemView,
    QAbstractScrollArea,
    QCheckBox,
    QComboBox,
    QFrame,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QScrollArea,
    QSizePolicy,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

__all__ = ["scroll_body", "side_by_side", "group", "wrapped_label", "button", "fit_dock",
           "Fold", "SCROLL_MIN_HEIGHT", "DOCK_WIDTH"]

SCROLL_MIN_HEIGHT = 48
#: px: the widest a dock asks to be (a laptop's canvas keeps >= 40 % of a 1280-px window)
DOCK_WIDTH = 380
#: characters a combo box shows at its narrowest
COMBO_CHARS = 12
#: px: a check box longer than this gets its text as a wrapped label beside it
CHECK_TEXT_WIDTH = 240
_UNBOUNDED = 16777215                 # Qt's QWIDGETSIZE_MAX: no maximum set


class _Scroll(QScrollArea):
    """A scroll area that asks for at most DOCK_WIDTH px (its content may ask for more)."""

    def sizeHint(self) -> QSize:
        hint = super().sizeHint()
        return QSize(min(hint.width(), DOCK_WIDTH), hint.height())


def scroll_body(widget: QWidget) -> QVBoxLayout:
    """Give `widget` a scroll area around a body widget; return the body's layout."""
    body = QWidget()
    area = _Scroll()
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
    """Magicgui widgets side by side, without labels."""
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


def fit_dock(widget: QWidget) -> None:
    """Let `widget`'s content fit a DOCK_WIDTH-px dock: no horizontal scroll bar, no height
    asked for that the content does not fill.

    Combo boxes shrink to COMBO_CHARS characters (their lists still show each choice whole),
    check boxes whose text is wider than CHECK_TEXT_WIDTH px show it as a wrapped label that
    toggles the box when clicked, and tables and lists with a maximum height ask for the
    height of their rows up to that maximum. Call once the widget's controls are laid out.
    A wrapped check box keeps its text as its accessible name; its ``text()`` is empty.

    Parameters
    ----------
    widget : QWidget
        A dock's widget; every combo box, check box and item view inside it is adjusted.
    """
    for view in widget.findChildren(QAbstractItemView):
        if view.maximumHeight() < _UNBOUNDED:
            view.setSizeAdjustPolicy(QAbstractScrollArea.AdjustToContents)
    for combo in widget.findChildren(QComboBox):
        combo.setSizeAdjustPolicy(QComboBox.AdjustToMinimumContentsLengthWithIcon)
        combo.setMinimumContentsLength(COMBO_CHARS)
    for box in widget.findChildren(QCheckBox):
        if box.fontMetrics().horizontalAdvance(box.text()) > CHECK_TEXT_WIDTH:
            _wrap_check_text(box)


class _CheckLabel(QLabel):
    """A check box's text, wrapped; clicking it toggles the box like its own text does."""

    def __init__(self, box: QCheckBox):
        super().__init__(box.text())
        self.box = box
        self.setWordWrap(True)
        self.setToolTip(box.toolTip())
        self.setSizePolicy(QSizePolicy.Preferred, QSizePolicy.Preferred)

    def mouseReleaseEvent(self, event) -> None:
        if self.box.isEnabled() and event.button() == Qt.LeftButton:
            self.box.click()
        super().mouseReleaseEvent(event)


def _wrap_check_text(box: QCheckBox) -> None:
    """Put `box` and its text as a wrapped label side by side, where the box was."""
    layout = box.parentWidget().layout() if box.parentWidget() is not None else None
    if layout is None:
        return
    row = QWidget()
    if layout.replaceWidget(box, row) is None:     # searches nested layouts too
        row.deleteLater()
        return
    label = _CheckLabel(box)
    box.setAccessibleName(box.text())
    box.setText("")
    box.setSizePolicy(QSizePolicy.Fixed, QSizePolicy.Fixed)
    row_layout = QHBoxLayout(row)
    row_layout.setContentsMargins(0, 0, 0, 0)
    row_layout.addWidget(box, 0, Qt.AlignTop)
    row_layout.addWidget(label, 1)


class Fold(QWidget):
    """A titled section that folds away behind an arrow (folded to start with).

    Parameters
    ----------
    title : str
        The arrow button's text.
    widgets : sequence of magicgui or Qt widgets
        The section's content, one under the other.
    folded : bool
        Whether the section starts folded.
    """

    def __init__(self, title: str, widgets, *, folded: bool = True,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.toggle = QToolButton()
        self.toggle.setText(title)
        self.toggle.setCheckable(True)
        self.toggle.setChecked(not folded)
        self.toggle.setToolButtonStyle(Qt.ToolButtonTextBesideIcon)
        self.toggle.setAutoRaise(True)
        self.toggle.setStyleSheet("QToolButton { border: none; }")
        self.body = QWidget()
        body_layout = QVBoxLayout(self.body)
        body_layout.setContentsMargins(12, 0, 0, 0)
        for widget in widgets:
            body_layout.addWidget(getattr(widget, "native", widget))
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addWidget(self.toggle)
        layout.addWidget(self.body)
        self.toggle.toggled.connect(self.set_open)
        self.set_open(not folded)

    @property
    def is_open(self) -> bool:
        return self.toggle.isChecked()

    def set_open(self, open_: bool = True) -> None:
        """Unfold (or fold) the section."""
        self.toggle.setChecked(open_)
        self.toggle.setArrowType(Qt.DownArrow if open_ else Qt.RightArrow)
        self.body.setVisible(open_)
