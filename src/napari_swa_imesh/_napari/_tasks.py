"""One way to run a computation: a generator in a napari thread worker, with a progress bar,
a status line, a Cancel button, and errors turned into notifications.

Every widget of the plugin runs its library calls through :class:`TaskPanel.run`. The
computation is a *steps* callable: it returns a generator that yields ``(done, total,
message)`` after each step and returns the result (the protocol of
``segment_steps``). The step total is the generator's own: the progress bar is
indeterminate until the first report and then counts to the total that report gives, so
no widget repeats a library's step count. The generator runs in a worker thread; the
result is handed to a callback in the main thread, the only place where layers are created
or changed.
Cancel asks the worker to stop at the next step boundary (a library call that is running
finishes first), and then no result callback runs. When the panel is destroyed (its widget
closed, or the viewer closed while a computation runs) the worker is asked to stop the same
way and cut off from every callback, so nothing it reports later reaches a deleted widget.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Generator
from typing import Any

from qtpy.QtCore import Signal
from qtpy.QtWidgets import QHBoxLayout, QLabel, QProgressBar, QPushButton, QVBoxLayout, QWidget

__all__ = ["TaskPanel", "notify_error", "notify_info", "notify_warning", "Steps"]

logger = logging.getLogger(__name__)

Steps = Callable[[], Generator[tuple[int, int, str], None, Any]]


def notify_error(message: str) -> None:
    """Show `message` as a napari error notification (what went wrong and what to do)."""
    from napari.utils.notifications import show_error

    show_error(message)


def notify_warning(message: str) -> None:
    from napari.utils.notifications import show_warning

    show_warning(message)


def notify_info(message: str) -> None:
    from napari.utils.notifications import show_info

    show_info(message)


def _relay(steps: Steps):
    """Worker body: run the steps generator, passing its reports and result through."""
    return (yield from steps())


def error_sentence(title: str, exc: BaseException) -> str:
    """One message for a failed computation.

    The library's ValueError/TypeError/OSError messages already say what to do; anything
    else is unexpected, so the user is told how to report it.
    """
    text = str(exc).strip() or type(exc).__name__
    if isinstance(exc, (ValueError, TypeError, OSError, MemoryError)):
        if isinstance(exc, MemoryError):
            text = "not enough memory; crop the image or use a larger scale."
        return f"{title} failed: {text}"
    return (f"{title} failed with an unexpected {type(exc).__name__}: {text}. Check the "
            "inputs; if they look right, report this with the image size and settings.")


class TaskPanel(QWidget):
    """Progress bar, status line and Cancel button for one widget's computations.

    Signals
    -------
    busy_changed(bool)
        Emitted when a computation starts (True) and when it has finished (False),
        whether it returned, failed or was cancelled.
    reported(int, int, str)
        A step report ``(done, total, message)`` of the running computation.
    """

    busy_changed = Signal(bool)
    reported = Signal(int, int, str)

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.worker = None
        self.title = ""
        self.last_error: str | None = None
        self.warnings: list[str] = []    # warnings the running (or last) computation raised
        self.progress_bar = QProgressBar()
        self.progress_bar.setTextVisible(True)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.cancel_button.setToolTip("Stop after the step that is running now.")
        self.cancel_button.clicked.connect(self.cancel)
        row = QHBoxLayout()
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(self.progress_bar, 1)
        row.addWidget(self.cancel_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(row)
        layout.addWidget(self.status)
        self._callbacks: tuple = (None, None)     # on_result, on_cancel of the running task

    @property
    def busy(self) -> bool:
        return self.worker is not None

    def run(self, steps: Steps, *, title: str,
            on_result: Callable[[Any], None], on_cancel: Callable[[], None] | None = None):
        """Run `steps` in a napari thread worker; call `on_result` with its result.

        Parameters
        ----------
        steps : callable
            Returns a generator yielding ``(done, total, message)`` and returning the result.
        title : str
            What the computation is (progress bar text, start of every message).
        on_result : callable
            Called in the main thread with the result.
        on_cancel : callable, optional
            Called in the main thread after a cancelled run.

        Returns
        -------
        GeneratorWorker or None
            The started worker; None (and a warning) when one is already running.
        """
        from napari.qt.threading import create_worker

        if self.busy:
            notify_warning(f"{self.title} is still running; wait for it or press Cancel "
                           "before starting another computation here.")
            return None
        # no total: napari's activity bar, like ours, waits for the generator's first report
        worker = create_worker(_relay, steps, _progress={"desc": title},
                               _ignore_errors=True, _start_thread=False)
        self.worker, self.title, self.last_error = worker, title, None
        self.warnings = []
        self.progress_bar.setRange(0, 0)      # busy until the generator reports its total
        self.progress_bar.setValue(0)
        self.progress_bar.setFormat(f"{title}: %v/%m")
        self.status.setText(f"{title}: starting")
        self.cancel_button.setEnabled(True)
        # only bound methods of this QObject: Qt drops them when the panel is destroyed
        # (its dock closed, or the viewer closed while a computation runs), so nothing
        # the worker reports later reaches a deleted widget; the worker is asked to stop
        self._callbacks = (on_result, on_cancel)
        worker.yielded.connect(self._on_yielded)
        # napari also shows them as notifications; kept here so widgets can say them too
        worker.warned.connect(self._on_warned)
        worker.returned.connect(self._on_returned)
        worker.errored.connect(self._on_errored)
        worker.aborted.connect(self._on_aborted)
        worker.finished.connect(self._on_finished)
        self.destroyed.connect(worker.quit)
        self.busy_changed.emit(True)
        worker.start()
        return worker

    def cancel(self) -> None:
        """Ask the running computation to stop at its next step."""
        if self.worker is not None:
            self.status.setText(f"{self.title}: cancelling after the current step")
            self.cancel_button.setEnabled(False)
            self.worker.quit()

    # -- main-thread callbacks -----------------------------------------------------------
    def _on_yielded(self, report) -> None:
        done, total, message = report
        self.progress_bar.setRange(0, max(int(total), 1))
        self.progress_bar.setValue(min(int(done), int(total)))
        self.status.setText(f"{self.title}: {message}")
        pbar = getattr(self.worker, "pbar", None)
        if pbar is not None:
            # napari counts yields; show the library's own step count instead
            if pbar.total != total:
                pbar.total = int(total)
            if pbar.n != done:
                pbar.update(int(done) - pbar.n)
            pbar.set_description(f"{self.title}: {message}")
        self.reported.emit(int(done), int(total), str(message))

    def _on_warned(self, show_warning_args: tuple) -> None:
        message = str(show_warning_args[0])
        if message not in self.warnings:
            self.warnings.append(message)

    def _on_returned(self, result) -> None:
        on_result = self._callbacks[0]
        try:
            on_result(result)
        except Exception as exc:  # a result the widget cannot show must still reach the user
            logger.exception("showing the result of %s", self.title)
            self._report(error_sentence(f"{self.title} (showing the result)", exc))
        else:
            self.status.setText(f"{self.title}: done")

    def _on_errored(self, exc: BaseException) -> None:
        logger.debug("%s failed", self.title, exc_info=exc)
        self._report(error_sentence(self.title, exc))

    def _report(self, message: str) -> None:
        self.last_error = message
        self.status.setText(message)
        notify_error(message)

    def _on_aborted(self) -> None:
        on_cancel = self._callbacks[1]
        self.status.setText(f"{self.title}: cancelled")
        notify_info(f"{self.title} cancelled; nothing was changed.")
        if on_cancel is not None:
            on_cancel()

    def _on_finished(self) -> None:
        try:
            self.destroyed.disconnect(self.worker.quit)
        except (TypeError, RuntimeError, AttributeError):
            pass
        self.worker = None
        self._callbacks = (None, None)
        self.cancel_button.setEnabled(False)
        self.busy_changed.emit(False)
