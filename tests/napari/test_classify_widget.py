"""Classify widget: signatures CSV, model save/load/apply to another image, sieve."""

import csv

import numpy as np
from scipy import ndimage as ndi
from swa_napari_helpers import draw_boxes, rect, wait_idle

from napari_swa_imesh._napari._classify_widget import METHOD_RECOMMENDED, METHOD_REFERENCE
from napari_swa_imesh._napari._sample_data import make_texture_mosaic
from napari_swa_imesh._napari._workflow import WorkflowWidget
from napari_swa_imesh.segmentation import dice_scores, load_model


def _classified(viewer, image, truth, qtbot, scale=4, method=METHOD_REFERENCE):
    flow = WorkflowWidget(viewer)
    flow.classify.method_combo.value = method
    flow.samples.truth_combo.value = truth
    flow.samples.per_material_spin.value = 16
    flow.samples.scale_spin.value = scale
    flow.samples.samples_from_truth()
    wait_idle(qtbot, flow.samples)
    flow.classify.scale_combo.value = scale
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    return flow


def test_signatures_model_round_trip_and_apply_to_another_image(mosaic_viewer, qtbot,
                                                                 tmp_path, notifications):
    viewer, image, truth = mosaic_viewer
    flow = _classified(viewer, image, truth, qtbot)
    classify = flow.classify
    result = classify.result

    classify.export_signatures(tmp_path / "sig.csv")
    with open(tmp_path / "sig.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["name"] for r in rows] == ["brick", "grass"]
    assert float(rows[1]["variance_mean"]) == result.signatures[1]["variance_mean"]

    classify.save_model(tmp_path / "model.npz")
    saved = load_model(tmp_path / "model.npz")
    assert saved.scale == 4 and saved.feature_set == "F1"
    assert saved.spacing == tuple(image.scale)

    # a second image: the same textures in another layout, not seen in training
    (other, kwargs, _), (other_truth, truth_kwargs, _) = make_texture_mosaic(layout="halves")
    other_layer = viewer.add_image(other, name="halves")
    classify.load_model(tmp_path / "model.npz")
    assert "scale 4" in classify.model_label.value
    classify.image_combo.value = other_layer
    classify.apply_model()
    wait_idle(qtbot, classify)
    labels = viewer.layers["halves SWA labels"]
    # a model refitted on the same tiles labels the training image identically
    np.testing.assert_array_equal(
        load_model(tmp_path / "model.npz").predict_tiles(image.data), result.tile_labels)
    dice = dice_scores(labels.data, other_truth)
    # measured 0.865 / 0.869 for a model fitted on the disc mosaic; chance is about 0.5
    assert dice[1] > 0.83 and dice[2] > 0.83, dice
    assert not notifications.errors


def test_sieve_removes_small_regions(mosaic_viewer, qtbot):
    viewer, image, truth = mosaic_viewer
    flow = _classified(viewer, image, truth, qtbot, scale=2)
    before = flow.classify.result.tile_labels
    flow.classify.sieve_spin.value = 50
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    after = flow.classify.result.tile_labels

    def n_regions(tiles):
        return sum(ndi.label(tiles == v)[1] for v in np.unique(tiles))

    assert n_regions(after) < n_regions(before)
    sizes = [np.bincount(ndi.label(after == v)[0].ravel())[1:].min() for v in np.unique(after)]
    assert min(sizes) >= 50


def test_recommended_is_the_default_and_beats_the_reference(mosaic_viewer, qtbot, tmp_path,
                                                            notifications):
    viewer, image, truth = mosaic_viewer
    ref_flow = _classified(viewer, image, truth, qtbot)   # keep it: its widgets live with it
    ref_dice = dice_scores(ref_flow.classify.result.labels, truth.data)
    assert ref_flow.classify.feature_combo.enabled
    fresh = WorkflowWidget(viewer)
    assert fresh.classify.method_combo.value == METHOD_RECOMMENDED
    flow = _classified(viewer, image, truth, qtbot, method=METHOD_RECOMMENDED)
    classify = flow.classify
    assert not classify.feature_combo.enabled and not classify.classifier_combo.enabled
    result = classify.result
    assert result.method == "recommended" and result.labels.shape == image.data.shape
    dice = dice_scores(viewer.layers[f"{image.name} SWA labels"].data, truth.data)
    # full-resolution labels follow the disc's curved edge that 16-px tiles cut into steps
    # (measured 0.962 / 0.909 against the reference's 0.911 / 0.800)
    assert all(dice[m] > ref_dice[m] + 0.03 for m in (1, 2)), (dice, ref_dice)
    assert "multiscale" in classify.scores.value
    classify.save_model(tmp_path / "rec.npz")
    assert load_model(tmp_path / "rec.npz").method == "recommended"
    classify.load_model(tmp_path / "rec.npz")
    classify.apply_model()
    wait_idle(qtbot, classify)
    np.testing.assert_array_equal(classify.result.labels, result.labels)
    assert not notifications.errors


def _unbalanced(viewer):
    """Brick boxes of 64 px and one grass box of 16 px: scale 4 windows (17 px) do not fit
    in any grass box."""
    flow = WorkflowWidget(viewer)
    draw_boxes(flow.samples, {"brick": [rect(0, 0, 64, 64), rect(0, 80, 64, 144)],
                              "grass": [rect(150, 150, 166, 230)]})
    return flow


def test_window_limit_is_said_before_the_run_and_after_it(mosaic_viewer, qtbot,
                                                          notifications):
    viewer, image, truth = mosaic_viewer
    flow = _unbalanced(viewer)
    classify = flow.classify
    assert classify.method_combo.value == METHOD_RECOMMENDED
    classify.scale_combo.value = 4
    _, sentence = flow.samples.current_samples().window_limit(4)
    # before any run: the panel says which box is too small and what to do
    assert sentence in classify.scale_note.value
    assert classify.scale_note.value.startswith("Next run: scale 4, set in this panel")
    classify.classify()
    assert any(sentence in w for w in notifications.messages("warning"))
    wait_idle(qtbot, classify)
    assert classify.tasks.last_error is None
    assert sentence in classify.scale_note.value      # still said next to the result
    # the reference method uses tiles, not windows: no window sentence
    classify.method_combo.value = METHOD_REFERENCE
    assert sentence not in classify.scale_note.value


def test_library_warnings_of_a_run_reach_the_panel(mosaic_viewer, qtbot, monkeypatch):
    """A warning the library raises in the worker is shown in the classify panel, not
    only as a passing notification."""
    import warnings

    from napari_swa_imesh._napari import _classify_widget

    real = _classify_widget.segment_steps

    def warning_steps(*args, **kwargs):
        warnings.warn("scale capped at 3: the largest box of 'grass' is 16x80 px",
                      UserWarning, stacklevel=2)
        return (yield from real(*args, **kwargs))

    monkeypatch.setattr(_classify_widget, "segment_steps", warning_steps)
    viewer, image, truth = mosaic_viewer
    flow = _unbalanced(viewer)
    flow.classify.method_combo.value = METHOD_REFERENCE
    flow.classify.scale_combo.value = 3
    flow.classify.classify()
    wait_idle(qtbot, flow.classify)
    assert flow.classify.result is not None
    note = flow.classify.scale_note.value
    assert note.startswith("Last run: tiles of scale 3: scale 3, set in this panel")
    assert "scale capped at 3: the largest box of 'grass' is 16x80 px" in note
