"""Closing the viewer while a computation runs (issue 23: a long session ended in a
segmentation fault at viewer.close()): nothing the worker reports afterwards reaches the
widgets that are gone, and no timer of theirs fires."""

import threading

from napari_swa_imesh._napari._workflow import WorkflowWidget


def test_viewer_closes_while_a_worker_runs(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    flow = WorkflowWidget(viewer)
    viewer.window.add_dock_widget(flow)
    release, finished, delivered = threading.Event(), threading.Event(), []

    def steps():
        yield 0, 2, "waiting"
        release.wait(30)             # the "long library call" still running at close
        yield 1, 2, "after the close"
        finished.set()
        return "result"

    panel = flow.classify.tasks
    worker = panel.run(steps, title="long run", on_result=delivered.append)
    assert worker is not None
    qtbot.waitUntil(lambda: panel.status.text() == "long run: waiting", timeout=10_000)
    clip_timer = flow.mesh.clip.timer
    viewer.close()
    qtbot.waitUntil(lambda: not panel_alive(flow), timeout=10_000)
    release.set()
    # the worker asked to stop at its next step: it never reaches its end, and its
    # report, result and end never reach the deleted panel
    qtbot.wait(300)
    assert worker.abort_requested
    assert not finished.is_set()
    assert delivered == []
    assert not timer_alive(clip_timer)


def panel_alive(flow) -> bool:
    try:
        flow.classify.tasks.status.text()
    except RuntimeError:
        return False
    return True


def timer_alive(timer) -> bool:
    try:
        timer.isActive()
    except RuntimeError:
        return False
    return True
