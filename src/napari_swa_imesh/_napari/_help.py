"""Tooltips from the glossary: every term a widget shows is defined where it appears.

:func:`explain_terms` walks a widget's labels, buttons, check boxes, group titles, tab titles
and combo-box items; for each glossary term in a text (:func:`.._glossary.terms_in`) it adds
the term's one-line definition to that element's tooltip, after the tooltip the widget
already had. Labels whose text changes after a run (result lines) are refreshed when their
tooltip is about to show, so a term that appears later is explained too. The definitions
come from :mod:`napari_swa_imesh._glossary`, the same the command line prints.
"""

from __future__ import annotations

from qtpy.QtCore import QEvent, QObject, Qt
from qtpy.QtWidgets import QAbstractButton, QComboBox, QGroupBox, QLabel, QTabWidget, QWidget

from .._glossary import define, terms_in

__all__ = ["explain_terms", "set_tooltip", "with_terms"]

_BASE = "_swa_base_tooltip"      # the tooltip a widget set itself, before any definition


def with_terms(tooltip: str, text: str) -> str:
    """`tooltip` followed by the definition of each glossary term in `text` it lacks."""
    lines = [tooltip] if tooltip else []
    for term in terms_in(text):
        line = f"{term}: {define(term)}"
        if line not in tooltip:
            lines.append(line)
    return "\n".join(lines)


def _text_of(widget: QWidget) -> str:
    if isinstance(widget, QGroupBox):
        return widget.title()
    if isinstance(widget, (QLabel, QAbstractButton)):
        return widget.text()
    return ""


def _refresh(widget: QWidget) -> None:
    base = widget.property(_BASE)
    if base is None:
        base = widget.toolTip()
        widget.setProperty(_BASE, base)
    widget.setToolTip(with_terms(str(base), _text_of(widget)))


class _Refresher(QObject):
    """Recomputes a label's tooltip from its current text just before it shows."""

    def eventFilter(self, obj, event):  # noqa: N802 (Qt's name)
        if event.type() == QEvent.ToolTip and isinstance(obj, QWidget):
            _refresh(obj)
        return False


def set_tooltip(widget: QWidget, text: str) -> None:
    """Give `widget` its own tooltip `text`, kept when the glossary's definitions are added."""
    widget.setProperty(_BASE, text)
    _refresh(widget)


def explain_terms(root: QWidget) -> None:
    """Add glossary definitions to the tooltips of everything in `root` that names a term.

    Safe to call again (definitions are never added twice).
    """
    refresher = root.findChild(_Refresher, "swa_term_refresher")
    if refresher is None:
        refresher = _Refresher(root)
        refresher.setObjectName("swa_term_refresher")
    for widget in [root, *root.findChildren(QWidget)]:
        if isinstance(widget, (QLabel, QAbstractButton, QGroupBox)):
            if widget.property(_BASE) is None:
                widget.installEventFilter(refresher)
            _refresh(widget)
        elif isinstance(widget, QComboBox):
            for i in range(widget.count()):
                text = widget.itemText(i)
                if terms_in(text):
                    tip = widget.itemData(i, Qt.ToolTipRole) or ""
                    widget.setItemData(i, with_terms(str(tip), text), Qt.ToolTipRole)
            items = " ".join(widget.itemText(i) for i in range(widget.count()))
            if terms_in(items):
                widget.setToolTip(with_terms(widget.toolTip(), items))
        elif isinstance(widget, QTabWidget):
            for i in range(widget.count()):
                widget.setTabToolTip(i, with_terms(widget.tabToolTip(i), widget.tabText(i)))
