"""The report box of the Simulate tab: per-material signatures and k_eff in one table.

Only the controls live here; the table is :func:`napari_swa_imesh.simulate.simulation_report`
(plain Python, tested without Qt). The signatures come from the classification that made
the labels (the Classify tab keeps them in the Labels layer's metadata) or from a CSV file
(``swa-imesh segment --signatures``, the Classify tab's export); the latest one chosen is
used. The report follows every run and every new signatures table.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from qtpy.QtWidgets import QFileDialog, QTableWidget, QTableWidgetItem

from ..simulate import simulation_report, write_report
from ._classify_widget import SEGMENTATION_KEY
from ._dock import Fold, button, side_by_side, wrapped_label
from ._signatures_input import SignaturesInput
from ._tasks import notify_error, notify_info, notify_warning

if TYPE_CHECKING:
    from ..simulate import SimulationReport, SimulationResult

__all__ = ["ReportPanel", "classification_signatures", "fill_table"]


def classification_signatures(labels_layer) -> list[dict] | None:
    """The signatures the Classify tab stored with a Labels layer, or None."""
    if labels_layer is None:
        return None
    rows = labels_layer.metadata.get(SEGMENTATION_KEY, {}).get("signatures")
    return [dict(r) for r in rows] if rows else None


def fill_table(table: QTableWidget, rows: list[list[str]], *, row_header: bool = False
               ) -> None:
    """Show text cells in a read-only table: first row the header (with `row_header`, the
    first column names the rows)."""
    header, *body = rows or [[]]
    start = 1 if row_header else 0
    table.clear()
    table.setColumnCount(len(header) - start)
    table.setRowCount(len(body))
    table.setHorizontalHeaderLabels([h.replace("_", " ") for h in header[start:]])
    if row_header:
        table.setVerticalHeaderLabels([r[0] for r in body])
    for i, row in enumerate(body):
        for j, text in enumerate(row[start:]):
            table.setItem(i, j, QTableWidgetItem(text))
    table.resizeColumnsToContents()


class ReportPanel(SignaturesInput):
    """Signatures source, the joined table, its warnings and the export button."""

    def __init__(self):
        self.signatures: list[dict] | None = None
        self.source = ""
        self.report: SimulationReport | None = None
        self._run: tuple | None = None              # (result, conductivity) of the last run
        self.source_label = wrapped_label()
        self.load_button = button("Load signatures CSV...", self._on_load_clicked,
                                  tooltip="A per-material table with a label and/or name "
                                          "column (swa-imesh segment --signatures, or the "
                                          "Classify tab's export).")
        self.export_button = button("Export report...", self._on_export_clicked,
                                    tooltip="The table and k_eff as .csv, .json or .md.")
        self.export_button.enabled = False
        self.table = QTableWidget(0, 0)
        self.table.setEditTriggers(QTableWidget.NoEditTriggers)
        self.table.verticalHeader().setVisible(False)
        self.table.setMaximumHeight(150)
        self.warnings_label = wrapped_label()
        self._show_source()

    def widget(self) -> Fold:
        """The report in a section that folds away (folded to start with)."""
        return Fold("signatures and k_eff report", [
            self.source_label, self.table, self.warnings_label,
            side_by_side(self.load_button, self.export_button)])

    # -- inputs ----------------------------------------------------------------------------
    def set_signatures(self, rows: list[dict] | None, source: str) -> None:
        """Join these signatures (None: none) to the runs from now on."""
        self.signatures, self.source = rows, source if rows else ""
        self._show_source()
        self.refresh()

    def set_result(self, result: SimulationResult | None, conductivity=None) -> None:
        """The run to report (its conductivity table as given to ``simulate``); None: no
        run (its mesh is gone), so no other labelling's signatures are joined to it."""
        self._run = None if result is None else (result, conductivity)
        self.refresh()

    # -- the report ------------------------------------------------------------------------
    def refresh(self) -> None:
        """Join the signatures to the last run and show the table and its warnings."""
        self.report = None
        self.export_button.enabled = False
        if self._run is None:
            fill_table(self.table, [])
            self.warnings_label.value = "simulate to fill the table"
            return
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)     # shown below instead
                self.report = simulation_report(*self._run, self.signatures)
        except ValueError as exc:
            fill_table(self.table, [])
            self.warnings_label.value = f"no report: {exc}"
            notify_error(f"the signatures do not fit this mesh: {exc}")
            return
        fill_table(self.table, self.report.table_rows())
        self.warnings_label.value = "\n".join(self.report.warnings)
        if self.report.warnings:
            notify_warning(" ".join(self.report.warnings))
        self.export_button.enabled = True

    def _show_source(self) -> None:
        self.source_label.value = (
            f"signatures: {self.source} ({len(self.signatures)} materials)" if self.signatures
            else "no signatures: classify the labels (Classify tab) or load a CSV; the "
                 "table then shows volume fractions and conductivities only")

    # -- files -----------------------------------------------------------------------------
    def export_report(self, path) -> Path | None:
        """Write the report (.csv, .json or .md by the suffix)."""
        if self.report is None:
            notify_error("simulate first; there is no report to export yet.")
            return None
        try:
            written = write_report(self.report, path, force=True)
        except (ValueError, OSError) as exc:
            notify_error(f"could not write the report: {exc}")
            return None
        notify_info(f"report written to {written}")
        return written

    def _on_export_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(None, "Export report", "report.csv",
                                              "CSV (*.csv);;JSON (*.json);;Markdown (*.md)")
        if path:
            self.export_report(path)
