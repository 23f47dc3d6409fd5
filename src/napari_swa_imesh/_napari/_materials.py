"""The material list of the samples widget and the table that shows it.

The list of :class:`Material` records is the data; the table is only its view. A name
typed in a cell or a colour picked by double-click replaces that record in the list and the
table is drawn again from the list; nothing is ever read back from cell text.
"""

from __future__ import annotations

from dataclasses import replace

from qtpy.QtCore import Qt, Signal
from qtpy.QtGui import QColor
from qtpy.QtWidgets import QColorDialog, QHeaderView, QTableWidget, QTableWidgetItem

from ..segmentation import Material
from ._layers import default_color

__all__ = ["MaterialTable"]

_LABEL, _NAME, _COLOR = range(3)


class MaterialTable(QTableWidget):
    """Label, name (editable) and colour (double-click to change) of each material.

    Signals
    -------
    edited()
        The user renamed or recoloured a material (:attr:`materials` already holds it).
    """

    edited = Signal()

    def __init__(self, parent=None):
        super().__init__(0, 3, parent)
        self.materials: list[Material] = []
        self.setHorizontalHeaderLabels(["label", "name", "colour"])
        self.horizontalHeader().setSectionResizeMode(_NAME, QHeaderView.Stretch)
        self.verticalHeader().setVisible(False)
        self.setSelectionBehavior(QTableWidget.SelectRows)
        self.setSelectionMode(QTableWidget.SingleSelection)
        self.setMaximumHeight(130)
        self.itemChanged.connect(self._on_item_changed)
        self.cellDoubleClicked.connect(self._on_double_clicked)

    def set_materials(self, materials: list[Material]) -> None:
        """Replace the list (colours filled in from the palette) and draw it."""
        self.materials = [m if m.color else replace(m, color=default_color(m.label))
                          for m in materials]
        self._render()

    def _render(self) -> None:
        current = self.currentRow()
        self.blockSignals(True)
        self.setRowCount(len(self.materials))
        for row, m in enumerate(self.materials):
            label = QTableWidgetItem(str(m.label))
            color = QTableWidgetItem("")
            color.setBackground(QColor(m.color))
            color.setToolTip("double-click to change")
            for item in (label, color):
                item.setFlags(item.flags() & ~Qt.ItemIsEditable)
            self.setItem(row, _LABEL, label)
            self.setItem(row, _NAME, QTableWidgetItem(m.name))
            self.setItem(row, _COLOR, color)
        self.blockSignals(False)
        if self.materials:
            self.selectRow(min(max(current, 0), len(self.materials) - 1))

    def _on_item_changed(self, item: QTableWidgetItem) -> None:
        if item.column() != _NAME or item.row() >= len(self.materials):
            return
        m = self.materials[item.row()]
        self.materials[item.row()] = replace(m, name=item.text().strip() or
                                             f"material {m.label}")
        self._render()
        self.edited.emit()

    def _on_double_clicked(self, row: int, column: int) -> None:
        if column != _COLOR:
            return
        m = self.materials[row]
        color = QColorDialog.getColor(QColor(m.color), self, "Material colour")
        if color.isValid():
            self.set_color(m.label, color.name())

    def set_color(self, label: int, color: str) -> None:
        """Give material `label` the colour `color` (what the colour dialog does)."""
        self.materials = [replace(m, color=color) if m.label == label else m
                          for m in self.materials]
        self._render()
        self.edited.emit()

    def current(self) -> Material | None:
        row = self.currentRow()
        return self.materials[row] if 0 <= row < len(self.materials) else None

    def select_label(self, label: int) -> None:
        """Select material `label` (ValueError when there is none)."""
        for row, m in enumerate(self.materials):
            if m.label == label:
                self.selectRow(row)
                return
        raise ValueError(f"no material with label {label}; add it first.")
