"""Run inside a fresh environment: dock every widget of the plugin's manifest and run the
workflow on the sample data, through napari's and npe2's own plugin machinery.

Exits 0 only when every widget docked, every step produced its result and napari raised no
error notification; prints one line per step. Started by ``test_napari_install.py``.
"""

from __future__ import annotations

import sys
import time

import npe2
from napari.utils.notifications import notification_manager
from qtpy.QtWidgets import QApplication

import napari
import napari_swa_imesh

PLUGIN = "napari-swa-imesh"
TIMEOUT = 120          # s per step: a stuck worker fails the check instead of hanging it


def wait(*widgets) -> None:
    start = time.monotonic()
    while any(w.tasks.busy for w in widgets):
        QApplication.processEvents()
        time.sleep(0.01)
        if time.monotonic() - start > TIMEOUT:
            sys.exit(f"{[type(w).__name__ for w in widgets]} still busy after {TIMEOUT} s")
    for widget in widgets:
        if widget.tasks.last_error:
            sys.exit(f"{type(widget).__name__}: {widget.tasks.last_error}")


def run_chain(samples, res, classify, mesh, simulate, truth) -> None:
    samples.truth_combo.value = truth
    samples.samples_from_truth()
    wait(samples)
    assert len(samples.samples_layer().data) > 0, "no sample boxes from the truth"
    res.select_layers(image=samples.image_layer(), samples=samples.samples_layer())
    res.compute()
    wait(res)
    assert res.stats is not None, "no RES statistics"
    classify.select_layers(image=samples.image_layer(), samples=samples.samples_layer())
    classify.classify()
    wait(classify)
    assert classify.result is not None, "no classification"
    mesh.select_labels(classify.viewer.layers[f"{classify.image_combo.value.name} SWA labels"])
    mesh.run_mesh()
    wait(mesh)
    assert mesh.mesh is not None and mesh.checks["all_passed"], "mesh missing or failed checks"
    simulate.select_mesh(mesh.surface_layer)
    simulate.run()
    wait(simulate)
    assert simulate.result is not None, "no simulation result"


def main() -> None:
    print("napari", napari.__version__, "npe2", npe2.__version__, "plugin from",
          napari_swa_imesh.__file__)
    if "site-packages" not in napari_swa_imesh.__file__:
        sys.exit("the plugin is not the installed wheel (source tree on sys.path?)")
    viewer = napari.Viewer(show=True)         # discovers the installed plugins
    manifest = npe2.PluginManager.instance().get_manifest(PLUGIN)
    names = [w.display_name for w in manifest.contributions.widgets]
    start = len(notification_manager.records)
    viewer.open_sample(PLUGIN, "texture_mosaic")
    truth = viewer.layers[-1]
    widgets = {}
    for name in names:
        _, widgets[name] = viewer.window.add_plugin_dock_widget(PLUGIN, name)
        print("docked", repr(name), type(widgets[name]).__name__)
    QApplication.processEvents()
    flow = widgets["Segment and mesh"]
    run_chain(flow.samples, flow.res, flow.classify, flow.mesh, flow.simulate, truth)
    print("workflow: boxes, RES, classification, mesh, k_eff", flow.simulate.result.k_eff)
    run_chain(*(widgets[n] for n in names[1:]), truth)
    print("the five step widgets ran the same chain")
    errors = [str(n.message) for n in notification_manager.records[start:]
              if str(n.severity).lower().endswith("error")]
    if errors:
        sys.exit(f"napari error notifications: {errors}")
    viewer.close()
    print("SMOKE OK")


if __name__ == "__main__":
    main()
