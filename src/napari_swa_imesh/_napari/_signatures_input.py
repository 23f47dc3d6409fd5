"""Loading a signatures CSV into a box of the Simulate tab (the report and the stochastic
box both take one): read, refuse with a notification, hand the rows on."""

from __future__ import annotations

from pathlib import Path

from qtpy.QtWidgets import QFileDialog

from ..simulate import read_signatures
from ._tasks import notify_error

__all__ = ["SignaturesInput"]


class SignaturesInput:
    """A mixin for a box with ``set_signatures(rows, source_name)``."""

    def set_signatures(self, rows: list[dict] | None, source: str) -> None:
        raise NotImplementedError

    def load_signatures(self, path) -> bool:
        """Read a signatures CSV; a file that is not one is refused with a notification."""
        try:
            rows = read_signatures(path)
        except (ValueError, OSError) as exc:
            notify_error(f"could not read the signatures: {exc}")
            return False
        self.set_signatures(rows, Path(path).name)
        return True

    def _on_load_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(None, "Load signatures", "", "CSV (*.csv)")
        if path:
            self.load_signatures(path)
