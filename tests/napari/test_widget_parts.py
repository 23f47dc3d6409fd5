"""The widgets' parts: layer pickers follow the layer list, the material list is the data
its table shows, the progress total comes from the computation."""

import numpy as np

from napari_swa_imesh._napari._layers import layer_picker, pick
from napari_swa_imesh._napari._materials import MaterialTable
from napari_swa_imesh._napari._samples_widget import SamplesWidget
from napari_swa_imesh._napari._tasks import TaskPanel
from napari_swa_imesh.segmentation import Material


def test_layer_picker_follows_the_layer_list_undocked(make_napari_viewer):
    viewer = make_napari_viewer()
    images = layer_picker(viewer, "Image", label="image")
    truths = layer_picker(viewer, "Labels", label="truth", none_text="(none)")
    assert images.value is None and truths.value is None
    a = viewer.add_image(np.zeros((4, 4)), name="a")
    viewer.add_labels(np.zeros((4, 4), int), name="t")
    b = viewer.add_image(np.ones((4, 4)), name="b")
    assert images.choices == (a, b) and images.value is a
    assert truths.choices[0] is None and truths.value is None     # "(none)" stays first
    pick(images, b)
    b.name = "renamed"
    assert [images.native.itemText(i) for i in range(2)] == ["a", "renamed"]
    viewer.layers.remove(a)
    assert images.choices == (b,) and images.value is b


def test_the_material_list_is_the_data_and_the_table_its_view(qtbot):
    table = MaterialTable()
    qtbot.addWidget(table)
    table.set_materials([Material(1, "brick"), Material(3, "grass", "#00ff00")])
    edits = []
    table.edited.connect(lambda: edits.append(list(table.materials)))
    assert table.materials[0].color is not None          # palette colour filled in
    table.item(0, 1).setText("  masonry ")               # the user types a name
    table.set_color(3, "#123456")                        # the colour dialog's choice
    assert table.materials == [Material(1, "masonry", table.materials[0].color),
                               Material(3, "grass", "#123456")]
    assert len(edits) == 2
    # the table is drawn again from the list: an empty name becomes the default one
    table.item(1, 1).setText("")
    assert table.materials[1].name == "material 3" == table.item(1, 1).text()
    table.select_label(3)
    assert table.current() is table.materials[1]


def test_samples_widget_keeps_its_materials_in_the_samples_layer(mosaic_viewer):
    viewer, image, _ = mosaic_viewer
    widget = SamplesWidget(viewer)
    layer = widget.new_samples_layer()
    widget.material_table.item(1, 1).setText("grass")
    assert [m.name for m in widget.materials()] == ["material 1", "grass"]
    assert [m["name"] for m in layer.metadata["swa_imesh_materials"]] == ["material 1", "grass"]


def test_progress_total_is_the_one_the_computation_reports(qtbot):
    panel = TaskPanel()
    qtbot.addWidget(panel)
    seen = []
    panel.reported.connect(lambda done, total, _: seen.append(
        (done, total, panel.progress_bar.maximum())))

    def steps():
        for done in range(8):
            yield done, 7, f"step {done}"
        return "result"

    results = []
    panel.run(steps, title="seven steps", on_result=results.append)
    assert panel.progress_bar.maximum() == 0          # busy until the first report
    qtbot.waitUntil(lambda: not panel.busy, timeout=60_000)
    assert results == ["result"]
    assert seen[0] == (0, 7, 7) and seen[-1] == (7, 7, 7)
