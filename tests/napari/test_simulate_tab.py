"""Simulate tab: protocol and refine (meshing the labels again), the field on a clipping
plane, the periodic tensor table and the signatures + k_eff report, against the library."""

import csv
import json

import numpy as np
import pytest
from swa_napari_helpers import Notifications, wait_idle

from napari_swa_imesh._napari._classify_widget import METHOD_REFERENCE
from napari_swa_imesh._napari._simulate_widget import FIELD_KEY
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.mesh import MeshClipper, shown_faces
from napari_swa_imesh.simulate import simulate, simulation_report
from napari_swa_imesh.simulate._remesh import mesh_refine

PERIODIC = "periodic"


def _layered(shape=(6, 8, 10)):
    labels = np.ones(shape, dtype=np.uint8)
    labels[..., shape[-1] // 2:] = 2
    labels[shape[0] // 2:, :, :2] = 3
    return labels


def _meshed_flow(viewer, qtbot, labels, name="layers"):
    layer = viewer.add_labels(labels, name=name)
    flow = WorkflowWidget(viewer)
    flow.mesh.select_labels(layer)
    flow.mesh.set_excluded([])
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh, timeout=120_000)
    return flow, layer


def _cells(table):
    return [[table.item(i, j).text() for j in range(table.columnCount())]
            for i in range(table.rowCount())]


def test_periodic_refined_run_meshes_the_labels_again_and_shows_the_tensor(
        make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = _layered()
    flow, layer = _meshed_flow(viewer, qtbot, labels)
    sim = flow.simulate
    assert sim.labels_combo.value is layer           # found by the mesh's name
    assert sim.refine_spin.value == 0 and "as shown" in sim.mesh_note.value
    sim.table.set_value(2, "10")
    sim.table.set_value(3, "0.5")
    sim.protocol_combo.value = PERIODIC
    assert "needs another mesh" in sim.mesh_note.value and "'layers' again" in \
        sim.mesh_note.value
    sim.refine_spin.value = 1
    assert "refine 1 with periodic faces" in sim.mesh_note.value
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    result = sim.result
    expected = simulate(labels, {1: 1.0, 2: 10.0, 3: 0.5}, refine=1, protocol=PERIODIC)
    # refine 1 at every interface; the periodic default does not adapt (matched faces)
    assert result.protocol == PERIODIC and mesh_refine(result.mesh) == 1
    assert "adapted" not in result.mesh.info and result.choice == "P2"
    assert result.mesh.n_cells == expected.mesh.n_cells
    assert np.allclose(result.tensor, expected.tensor, rtol=1e-9)
    # the Mesh tab's mesh is unchanged; the field is drawn on the run's mesh
    assert mesh_refine(flow.mesh.mesh) == 0 and flow.mesh.mesh.n_cells < result.mesh.n_cells
    assert len(sim.field_layer.data[0]) == len(result.mesh.points)
    # the tensor table: rows and columns x, y, z, the values to 6 digits
    assert sim.tensor_table.isVisibleTo(sim)
    assert _cells(sim.tensor_table) == [[f"{v:.6g}" for v in row] for row in result.tensor]
    headers = [sim.tensor_table.horizontalHeaderItem(j).text() for j in range(3)]
    assert headers == ["x", "y", "z"]
    # the potential of a periodic run is x + fluctuation: the colour range is its extent
    u = result.potential["x"]
    assert tuple(sim.field_layer.contrast_limits) == pytest.approx((u.min(), u.max()))
    assert sim.figure.axes[0].get_xlim() == pytest.approx((u.min(), u.max()))
    # back to the mixed protocol on the mesh as shown: no tensor table
    sim.protocol_combo.value = "mixed"
    sim.refine_spin.value = 0
    assert "as shown" in sim.mesh_note.value
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    # the default adapts it once (the labels are at hand); P1 runs on it as it is
    assert sim.result.mesh.recipe.adapted.from_refine == 0
    assert "where the flux jumps" in sim.mesh_note.value
    sim.order_combo.value = "P1 (linear)"
    assert "where the flux jumps" not in sim.mesh_note.value
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    assert sim.result.mesh is flow.mesh.mesh and not sim.tensor_table.isVisibleTo(sim)
    # P1 adapted: two steps on the labels, within 3x the vertices of the mesh shown
    sim.order_combo.value = "P1, refined twice where the flux jumps (at most 3x the vertices)"
    assert "within 2.9x the vertices" in sim.mesh_note.value
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    assert sim.result.order == 1 and sim.result.adapt == 2
    assert flow.mesh.mesh.n_cells < sim.result.mesh.n_cells
    assert len(sim.result.mesh.points) <= 3 * len(flow.mesh.mesh.points)


def test_the_field_follows_the_clipping_plane(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = _layered()
    flow, _ = _meshed_flow(viewer, qtbot, labels)
    sim = flow.simulate
    sim.table.set_value(2, "4")
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    result = sim.result
    field = sim.field_layer
    whole = shown_faces(result.mesh.cells, result.mesh.material)[0]
    assert np.array_equal(field.data[1], whole)
    assert sim.clip.enable_box.enabled and "not clipped" in sim.clip.status.value

    sim.show_combo.value = "y"
    clip = sim.clip
    clip.axis_combo.value = 1                       # rows: the plane y = position
    clip.keep_combo.value = "above"
    clip.position_slider.value = 3.3
    clip.enable_box.value = True
    qtbot.waitUntil(lambda: len(field.data[1]) != len(whole), timeout=5_000)
    kept, faces, _ = MeshClipper(result.mesh).faces(1, 3.3, keep="above")
    assert np.array_equal(np.sort(field.data[1], axis=1), np.sort(faces, axis=1))
    assert np.array_equal(field.data[2], result.potential["y"])
    assert field.metadata[FIELD_KEY] == "y"
    assert tuple(field.contrast_limits) == pytest.approx((0.0, 1.0))
    # every vertex drawn belongs to an element the clip keeps whole
    assert np.isin(field.data[1], result.mesh.cells[kept]).all()
    assert f"{np.count_nonzero(kept)} of {result.mesh.n_cells} elements" in clip.status.value
    # the drawn faces are the mesh's own boundary or the cut: the potential stays 0..1
    assert np.isclose(field.data[2][result.mesh.points[:, 1] == 0].max(), 0.0)
    clip.enable_box.value = False
    qtbot.waitUntil(lambda: len(field.data[1]) == len(whole), timeout=5_000)
    assert np.array_equal(field.data[1], whole)


def test_refine_without_the_labels_or_with_other_labels_is_refused(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = _layered()
    flow, _ = _meshed_flow(viewer, qtbot, labels)
    sim = flow.simulate
    notes = Notifications()
    sim.labels_combo.value = None
    sim.refine_spin.value = 2
    assert "pick the labels it was made from" in sim.mesh_note.value
    assert sim.run() is None
    assert any("need a new mesh: pick the labels" in m for m in notes.errors)
    other = labels.copy()
    other[0, 0, 0] = 2
    sim.labels_combo.value = viewer.add_labels(other, name="other")
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    assert sim.result is None
    assert any("not the image the mesh was made from" in m for m in notes.errors)


def test_report_joins_the_classification_signatures_to_k_eff(mosaic_viewer, qtbot, tmp_path):
    viewer, image, truth = mosaic_viewer
    flow = WorkflowWidget(viewer)
    flow.classify.method_combo.value = METHOD_REFERENCE
    flow.samples.truth_combo.value = truth
    flow.samples.per_material_spin.value = 16
    flow.samples.scale_spin.value = 4
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.classify.scale_combo.value = 4
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh, timeout=120_000)
    sim, panel = flow.simulate, flow.simulate.report
    labels = viewer.layers[f"{image.name} SWA labels"]
    assert sim.labels_combo.value is labels
    assert panel.source_label.value == f"signatures: classification of {labels.name!r} " \
                                       "(2 materials)"
    sim.labels_combo.value = truth                   # not classified: no signatures of its own
    assert panel.signatures is None and panel.source_label.value.startswith("no signatures")
    sim.labels_combo.value = labels
    assert len(panel.signatures) == 2
    sim.table.set_value(2, "10")
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    signatures = flow.classify.result.signatures
    expected = simulation_report(sim.result, {1: 1.0, 2: 10.0}, signatures)
    assert _cells(panel.table) == expected.table_rows()[1:]
    header = [panel.table.horizontalHeaderItem(j).text() for j in range(4)]
    assert header == ["label", "name", "volume fraction", "conductivity"]
    assert panel.report.materials[1]["name"] == "grass"
    assert panel.report.materials[1]["variance_mean"] == signatures[1]["variance_mean"]
    fraction = np.mean(labels.data == 2)
    assert panel.report.materials[1]["volume_fraction"] == pytest.approx(fraction, rel=1e-12)
    # no material warning; a mesh layer is not meshed again, so a wide interval is said
    assert all(w.startswith("the interval along") for w in panel.report.warnings)
    assert "not in the mesh" not in panel.warnings_label.value

    assert panel.export_report(tmp_path / "report.csv") is not None
    with open(tmp_path / "report.csv", newline="") as f:
        lines = list(csv.reader(f))
    k_row = lines[lines.index([]) + 2]
    assert k_row[0] == "k_eff" and float(k_row[1]) == pytest.approx(sim.result.k_eff["x"],
                                                                     rel=1e-14)
    assert float(lines[2][lines[0].index("variance_mean")]) == \
        pytest.approx(signatures[1]["variance_mean"], rel=1e-14)

    # a CSV with a material the mesh lacks: its row stays, and the panel says so
    (tmp_path / "sig.csv").write_text("label,name,tiles\n1,brick,5\n2,grass,6\n3,moon,7\n")
    notes = Notifications()
    assert panel.load_signatures(tmp_path / "sig.csv")
    assert "sig.csv (3 materials)" in panel.source_label.value
    assert _cells(panel.table)[2][:3] == ["3", "moon", ""]
    assert "material 3 (moon) has a signature but is not in the mesh" in \
        panel.warnings_label.value
    assert any("material 3 (moon)" in m for m in notes.messages("warning"))
    saved = json.loads(panel.export_report(tmp_path / "report.json").read_text())
    assert [r["tiles"] for r in saved["materials"]] == [5, 6, 7]
    assert saved["warnings"] == panel.report.warnings
    # a table that is not signatures is refused and the last one kept
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    assert not panel.load_signatures(tmp_path / "bad.csv")
    assert any("no 'label' or 'name' column" in m for m in notes.errors)
    assert "sig.csv" in panel.source_label.value


def test_a_mesh_of_names_the_signatures_contradict_gives_no_report(make_napari_viewer, qtbot,
                                                                   tmp_path):
    viewer = make_napari_viewer()
    labels = np.ones((8, 10), dtype=np.uint8)
    labels[:, 5:] = 2
    layer = viewer.add_labels(labels, name="named", metadata={
        "material_names": {1: "soft", 2: "hard"}})
    flow = WorkflowWidget(viewer)
    flow.mesh.select_labels(layer)
    flow.mesh.set_excluded([])
    flow.mesh.run_mesh()
    wait_idle(qtbot, flow.mesh, timeout=120_000)
    assert flow.mesh.mesh.material_names == {1: "soft", 2: "hard"}
    sim = flow.simulate
    sim.run()
    wait_idle(qtbot, sim, timeout=120_000)
    (tmp_path / "sig.csv").write_text("label,name,tiles\n1,hard,5\n2,soft,6\n")
    notes = Notifications()
    sim.report.load_signatures(tmp_path / "sig.csv")
    assert sim.report.report is None and not sim.report.export_button.enabled
    assert "another labelling" in sim.report.warnings_label.value
    assert any("another labelling" in m for m in notes.errors)
