"""Mesh widget: the histogram shades the bound the library proves for the mesh's voxels;
the clip shows the whole elements on one side of a plane, in the same layer."""

import numpy as np
import pytest
from swa_napari_helpers import wait_idle

from napari_swa_imesh._napari._mesh_widget import COLOR_BY_MATERIAL, MeshWidget
from napari_swa_imesh.mesh import MeshClipper, quality_bounds, quality_table, radius_edge_ratio

REGULAR = {2: [[0, 0], [1, 0], [0.5, np.sqrt(3) / 2]],
           3: [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]}


def _band(widget):
    """(lo, hi, label) of the shaded bound in the histogram."""
    (ax,) = widget.figure.axes
    (band,) = [p for p in ax.patches if p.get_gid() == "bound"]
    return band.get_x(), band.get_x() + band.get_width(), band.get_label()


def _meshed(viewer, qtbot, data, *, scale=None):
    labels = viewer.add_labels(data, scale=scale)
    widget = MeshWidget(viewer)
    widget.select_labels(labels)
    widget.set_excluded([])
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    return widget


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
    lo, hi, label = _band(widget)
    assert label == "IMESH bound, square/cubic voxels"
    # from the regular simplex to the worst element the templates can make
    regular = radius_edge_ratio(np.array(REGULAR[ndim], float), np.arange(ndim + 1)[None])[0]
    worst = max(row["radius_edge_ratio"] for row in quality_table(ndim))
    assert (lo, hi) == pytest.approx((regular, worst), abs=1e-12)
    assert hi == pytest.approx(1 / np.sqrt(2) if ndim == 2 else np.sqrt(5) / 2)
    # every element of the template mesh lies in the shaded range
    assert widget.mesh.quality.max() <= hi + 1e-9


def test_anisotropic_voxels_shade_their_own_bound_not_the_cubic_one(make_napari_viewer, qtbot):
    rng = np.random.default_rng(5)
    viewer = make_napari_viewer()
    data = rng.integers(1, 4, (8, 10, 10)).astype(np.uint8)
    # default: 2:1:1 voxels are cut into 2 x 1 x 1 cubic cells, and the cubic bound holds
    widget = _meshed(viewer, qtbot, data, scale=(2.0, 1.0, 1.0))
    lo, hi, label = _band(widget)
    cubic = quality_bounds(3)["quality"][1]
    assert label == "IMESH bound, 2:1:1 voxels in 2 x 1 x 1 cells"
    assert hi == pytest.approx(cubic)
    assert widget.mesh.quality.max() <= hi + 1e-9
    assert "2:1:1 voxels cut into 2 x 1 x 1 cells: ratio <= 1.118" in widget.summary.value
    # stretched voxels: their own (worse) bound, and the cubic one is said not to hold
    widget.subdivide_box.value = False
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    lo, hi, label = _band(widget)
    assert label == "IMESH bound, 2:1:1 voxels"
    assert hi == pytest.approx(
        quality_bounds(3, spacing=(2.0, 1.0, 1.0), subdivide=False)["quality"][1])
    assert cubic + 0.1 < widget.mesh.quality.max() <= hi + 1e-9
    assert "2:1:1 voxels: ratio <= 2.550" in widget.summary.value
    assert f"cubic {cubic:.3f} does not hold" in widget.summary.value


def test_max_aspect_reaches_the_mesher_and_its_bound_is_shaded(make_napari_viewer, qtbot):
    rng = np.random.default_rng(6)
    viewer = make_napari_viewer()
    data = rng.integers(1, 3, (6, 8, 8)).astype(np.uint8)
    # 2.5:1:1 voxels: 2 x 1 x 1 cells at the default 1.25, 3 x 1 x 1 at 1.2 (2.5/3 = 0.83)
    widget = _meshed(viewer, qtbot, data, scale=(2.5, 1.0, 1.0))
    assert widget.max_aspect_spin.value == 1.25
    assert widget.mesh.recipe.lattice.factors == (2, 1, 1)
    widget.max_aspect_spin.value = 1.2
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    info = widget.mesh.recipe.lattice.describe()
    assert info["factors"] == [3, 1, 1] and info["max_aspect"] == 1.2
    lo, hi, label = _band(widget)
    assert label == "IMESH bound, 2.5:1:1 voxels in 3 x 1 x 1 cells"
    assert hi == pytest.approx(
        quality_bounds(3, spacing=(2.5, 1.0, 1.0), max_aspect=1.2)["quality"][1])
    assert widget.mesh.quality.max() <= hi + 1e-9 < 1.32


def test_refine_and_max_edge_reach_the_mesher(make_napari_viewer, qtbot):
    viewer = make_napari_viewer()
    data = np.ones((12, 12, 12), np.uint8)
    data[4:8, 4:8, 4:8] = 2
    widget = _meshed(viewer, qtbot, data)
    plain = widget.mesh.n_cells
    widget.refine_spin.value = 1
    widget.max_size_spin.value = 4.0
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    mesh = widget.mesh
    assert mesh.recipe.lattice.refine == 1 and mesh.recipe.max_size == 4.0
    assert mesh.n_cells > plain
    corners = mesh.points[mesh.cells]
    assert np.linalg.norm(corners[:, :, None] - corners[:, None], axis=-1).max() <= 4.0


def _faces(layer):
    vertices, triangles, _ = layer.data
    return {tuple(sorted(map(tuple, np.round(vertices[t], 9).tolist()))) for t in triangles}


def _expected(widget, axis, position, keep):
    surface = MeshClipper(widget.mesh).surface(axis, position, keep=keep)
    return {tuple(sorted(map(tuple, np.round(surface["vertices"][t], 9).tolist())))
            for t in surface["triangles"]}


def test_the_clip_slider_shows_the_kept_elements_in_the_same_layer(make_napari_viewer, qtbot):
    rng = np.random.default_rng(3)
    viewer = make_napari_viewer()
    widget = _meshed(viewer, qtbot, rng.integers(1, 4, (8, 12, 10)).astype(np.uint8),
                     scale=(2.0, 1.0, 1.0))
    layer = widget.surface_layer
    full = _faces(layer)
    clip = widget.clip
    assert not clip.active and clip.status.value.startswith("not clipped")

    clip.axis_combo.value = 1                                 # y: rows
    assert (clip.position_slider.min, clip.position_slider.max) == (0.0, 12.0)
    clip.enable_box.value = True
    qtbot.waitUntil(lambda: _faces(layer) != full, timeout=5_000)
    assert viewer.layers[-1] is layer and len(viewer.layers) == 2   # updated in place
    axis, position, keep = clip.settings()
    assert (axis, position, keep) == (1, 6.0, "below")
    assert _faces(layer) == _expected(widget, 1, 6.0, "below")
    before = _faces(layer)

    # a burst of slider moves draws once, for the last position
    drawn, draw = [], clip._on_change
    clip._on_change = lambda: (drawn.append(clip.settings()[1]), draw())
    for value in np.linspace(3.0, 8.5, 12):
        clip.position_slider.value = value
    qtbot.waitUntil(lambda: len(drawn) > 0, timeout=5_000)
    qtbot.wait(200)
    position = clip.position_slider.value
    assert drawn == [position] and abs(position - 8.5) < 0.05
    after = _faces(layer)
    assert after != before and after == _expected(widget, 1, position, "below")
    assert f"of {widget.mesh.n_cells} elements kept whole" in clip.status.value

    # the other side, coloured by material: one colour per vertex drawn
    clip.keep_combo.value = "above"
    qtbot.waitUntil(lambda: _faces(layer) != after, timeout=5_000)
    assert _faces(layer) == _expected(widget, 1, position, "above")
    widget.color_combo.value = COLOR_BY_MATERIAL
    assert len(layer.vertex_colors) == len(layer.data[0])

    # off again: the whole mesh's faces
    clip.enable_box.value = False
    qtbot.waitUntil(lambda: _faces(layer) == full, timeout=5_000)
    assert len(layer.vertex_colors) == len(layer.data[0])


def test_delaunay_is_not_given_a_bound_and_2d_meshes_clip_too(make_napari_viewer, qtbot):
    rng = np.random.default_rng(8)
    viewer = make_napari_viewer()
    labels = viewer.add_labels(rng.integers(1, 4, (12, 16)).astype(np.uint8))
    widget = MeshWidget(viewer)
    widget.select_labels(labels)
    widget.set_excluded([])
    widget.method_combo.value = "delaunay"
    widget.run_mesh()
    wait_idle(qtbot, widget, timeout=120_000)
    assert _band(widget)[2] == "template bound, square/cubic voxels (delaunay proves none)"
    assert "no quality bound is proven for the delaunay method" in widget.summary.value
    clip = widget.clip
    assert list(clip.axis_combo.choices) == [0, 1]
    layer, n = widget.surface_layer, widget.mesh.n_cells
    clip.axis_combo.value = 1
    clip.enable_box.value = True
    qtbot.waitUntil(lambda: len(layer.data[1]) < n, timeout=5_000)
    kept = MeshClipper(widget.mesh).kept(1, clip.settings()[1])
    assert len(layer.data[1]) == kept.sum() > 0
