"""Mesh widget: the histogram shades the IMESH bound range the library proves."""

import numpy as np
import pytest
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._mesh_widget import MeshWidget
from napari_swa_imesh.mesh import quality_table, radius_edge_ratio

REGULAR = {2: [[0, 0], [1, 0], [0.5, np.sqrt(3) / 2]],
           3: [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]}


@pytest.mark.parametrize("ndim", [2, 3])
def test_histogram_shades_the_range_of_quality_table(make_napari_viewer, qtbot, ndim):
    rng = np.random.default_rng(ndim)
    viewer = make_napari_viewer()
    labels = viewer.add_labels(rng.integers(1, 4, (12,) * ndim).astype(np.uint8))
    widget = MeshWidget(viewer)
    widget.select_labels(labels)
    widget.set_excluded([])
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    (ax,) = widget.figure.axes
    (band,) = [p for p in ax.patches if p.get_label() == "IMESH bound range"]
    lo, hi = band.get_x(), band.get_x() + band.get_width()
    # from the regular simplex to the worst element the templates can make
    regular = radius_edge_ratio(np.array(REGULAR[ndim], float), np.arange(ndim + 1)[None])[0]
    worst = max(row["radius_edge_ratio"] for row in quality_table(ndim))
    assert (lo, hi) == pytest.approx((regular, worst), abs=1e-12)
    assert hi == pytest.approx(1 / np.sqrt(2) if ndim == 2 else np.sqrt(5) / 2)
    # every element of the template mesh lies in the shaded range
    assert widget.mesh.quality.max() <= hi + 1e-9
