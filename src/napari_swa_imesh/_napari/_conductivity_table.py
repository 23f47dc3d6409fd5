"""The conductivity table of the Simulate tab: one editable row per material of the mesh."""

from __future__ import annotations

from dataclasses import dataclass

from qtpy.QtCore import Qt, Signal
from qtpy.QtWidgets import QTableWidget, QTableWidgetItem, QWidget

__all__ = ["Conductivity", "ConductivityTable", "parse_conductivity"]


@dataclass(frozen=True)
class Conductivity:
    """One row of the table: a material and the text of its conductivity."""

    label: int
    name: str
    text: str = "1"


def parse_conductivity(text: str) -> float | list[float]:
    """``"2.5"`` -> 2.5; ``"1, 2, 3"`` -> the diagonal in x, y(, z) order.

    Raises
    ------
    ValueError
        Text that is not a number or a comma list of numbers.
    """
    try:
        numbers = [float(t) for t in text.replace(";", ",").split(",") if t.strip()]
    except ValueError:
        numbers = []
    if not numbers:
        raise ValueError(f"conductivity {text!r} is not a number (or a comma list of "
                         "numbers for the diagonal in x, y, z order).")
    return numbers[0] if len(numbers) == 1 else numbers


class ConductivityTable(QTableWidget):
    """Material | name | conductivity; the records list is the data, the table its view."""

    edited = Signal()

    def __init__(self, parent: QWidget | None = None):
        super().__init__(0, 3, parent)
        self.setHorizontalHeaderLabels(["material", "name", "conductivity k"])
        self.horizontalHeader().setStretchLastSection(True)
        self.verticalHeader().setVisible(False)
        self.setMaximumHeight(150)
        self.setToolTip("Conductivity (or diffusivity) per material: a positive number, or "
                        "one number per axis (x, y in 2-D; x, y, z in 3-D) for a diagonal "
                        "tensor.")
        self.records: list[Conductivity] = []
        self.itemChanged.connect(self._on_item_changed)

    def set_records(self, records: list[Conductivity]) -> None:
        self.records = list(records)
        self.blockSignals(True)
        self.setRowCount(len(self.records))
        for row, record in enumerate(self.records):
            for col, text in enumerate((str(record.label), record.name, record.text)):
                item = QTableWidgetItem(text)
                if col < 2:
                    item.setFlags(item.flags() & ~Qt.ItemIsEditable)
                self.setItem(row, col, item)
        self.blockSignals(False)

    def set_value(self, label: int, text: str) -> None:
        """Set one material's conductivity text (as an edit in the table would)."""
        self.set_records([Conductivity(r.label, r.name, text) if r.label == label else r
                          for r in self.records])
        self.edited.emit()

    def conductivity(self) -> dict[int, float | list[float]]:
        """{label: value} of every row; ValueError names a row that is not a number."""
        return {r.label: parse_conductivity(r.text) for r in self.records}

    def _on_item_changed(self, item: QTableWidgetItem) -> None:
        if item.column() == 2 and item.row() < len(self.records):
            record = self.records[item.row()]
            self.records[item.row()] = Conductivity(record.label, record.name, item.text())
            self.edited.emit()
