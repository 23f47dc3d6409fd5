"""The mesh coloured by quality has its legend on the canvas: the colour bar of the layer
and a line with the scale, the bound and the worst element (issue 23, sec. 3)."""

import numpy as np
import pytest
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._mesh_widget import (
    COLOR_BY_MATERIAL,
    COLOR_BY_QUALITY,
    MeshWidget,
    bound_range,
    text_overlay,
)


@pytest.mark.parametrize("ndim", [2, 3])
def test_quality_colouring_shows_its_colour_bar_and_bound(make_napari_viewer, qtbot, ndim):
    rng = np.random.default_rng(ndim)
    viewer = make_napari_viewer()
    labels = viewer.add_labels(rng.integers(1, 4, (10,) * ndim).astype(np.uint8))
    widget = MeshWidget(viewer)
    widget.select_labels(labels)
    widget.set_excluded([])
    assert widget.color_combo.value == COLOR_BY_QUALITY
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    layer, mesh = widget.surface_layer, widget.mesh
    lo, hi = bound_range(mesh.ndim, mesh.spacing)
    worst = float(mesh.quality.max())
    # the colour bar is the layer's own: its colours are the layer's colormap and limits
    assert layer.colorbar.visible
    assert layer.colormap.name == "turbo"
    np.testing.assert_allclose(layer.contrast_limits, [lo, max(hi, worst)], atol=1e-8)
    text = text_overlay(viewer).text
    assert text_overlay(viewer).visible
    assert "radius-to-edge ratio" in text
    assert f"<= {hi:.3f}" in text and f"worst element {worst:.3f} (within the bound)" in text
    # coloured by material, the quality legend goes away (and comes back)
    widget.color_combo.value = COLOR_BY_MATERIAL
    assert not layer.colorbar.visible and not text_overlay(viewer).visible
    widget.color_combo.value = COLOR_BY_QUALITY
    assert layer.colorbar.visible and text_overlay(viewer).text == text
    # the text belongs to the mesh layer: hidden (a potential field shown instead) or
    # removed, the canvas shows no quality legend over something else
    layer.visible = False
    assert not text_overlay(viewer).visible
    layer.visible = True
    assert text_overlay(viewer).visible
    viewer.layers.remove(layer)
    assert not text_overlay(viewer).visible


def test_the_legend_leaves_other_text_alone(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    labels = viewer.add_labels(np.random.default_rng(0).integers(1, 3, (8, 8)).astype(np.uint8))
    widget = MeshWidget(viewer)
    widget.select_labels(labels)
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    text_overlay(viewer).text = "someone else's note"
    widget.color_combo.value = COLOR_BY_MATERIAL
    assert text_overlay(viewer).text == "someone else's note"
