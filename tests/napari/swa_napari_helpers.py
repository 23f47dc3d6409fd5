"""Helpers shared by the widget tests (imported by name: this folder is on sys.path)."""

from __future__ import annotations

# small enough that the whole napari suite runs in a few minutes on two shared cores, large
# enough that the grey-matter shell of the phantom still holds sample blocks
PHANTOM_SHAPE = (48, 64, 64)


def add_layer_data(viewer, layer_data):
    """Add napari LayerData tuples (what a sample-data command returns) to `viewer`."""
    return [getattr(viewer, f"add_{kind}")(data, **kwargs) for data, kwargs, kind in layer_data]


class Notifications:
    """napari notifications dispatched during a test (errors, warnings, infos)."""

    def __init__(self):
        from napari.utils.notifications import notification_manager

        self.manager = notification_manager
        self.start = len(notification_manager.records)

    @property
    def all(self):
        return self.manager.records[self.start:]

    def messages(self, severity: str | None = None) -> list[str]:
        return [str(n.message) for n in self.all
                if severity is None or str(n.severity).lower().endswith(severity)]

    @property
    def errors(self) -> list[str]:
        return self.messages("error")


def wait_idle(qtbot, *widgets, timeout=60_000):
    """Wait until every widget's TaskPanel has finished its computation."""
    qtbot.waitUntil(lambda: all(not w.tasks.busy for w in widgets), timeout=timeout)
