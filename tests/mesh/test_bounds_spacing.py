"""quality_bounds with a spacing: the bound that holds for the voxels actually used."""

import numpy as np
import pytest
from imesh_cases import cases

from napari_swa_imesh.mesh import mesh_labels, quality_bounds


@pytest.mark.parametrize("d", [2, 3])
def test_equal_spacing_is_the_cubic_bound(d):
    assert quality_bounds(d, spacing=2.5) == quality_bounds(d)
    assert quality_bounds(d, spacing=(0.3,) * d) == quality_bounds(d)


@pytest.mark.parametrize("d", [2, 3])
def test_stretched_templates_tend_to_the_exhaustive_table(d):
    # the spacing bound runs over every template simplex, the cubic one over the leaf
    # configurations the tree can make: at a stretch of 1 + 1e-9 the two must agree
    near = quality_bounds(d, spacing=(1.0,) * (d - 1) + (1.0 + 1e-9,))
    for name, (lo, hi) in quality_bounds(d).items():
        assert near[name] == pytest.approx((lo, hi), rel=1e-6), name


@pytest.mark.parametrize("d,spacing", [(2, (2.0, 1.0)), (2, (1.0, 3.0)),
                                       (3, (2.0, 1.0, 1.0)), (3, (1.0, 0.5, 3.0))])
def test_every_element_of_a_stretched_mesh_lies_in_its_bound(d, spacing):
    bounds = quality_bounds(d, spacing=spacing, subdivide=False)
    cubic = quality_bounds(d)
    worst = 0.0
    for name, labels in cases(d):
        mesh = mesh_labels(labels, spacing=spacing, subdivide=False)
        for metric, (lo, hi) in bounds.items():
            values = mesh.cell_data[metric]
            assert (values >= lo - 1e-9).all() and (values <= hi + 1e-9).all(), (name, metric)
        worst = max(worst, float(mesh.quality.max()))
    # the bound is reached, and the cubic one would be a false claim for these voxels
    assert worst == pytest.approx(bounds["quality"][1])
    assert worst > cubic["quality"][1] + 0.1


@pytest.mark.parametrize("d,spacing", [(2, (2.0, 1.0)), (2, (1.0, 3.0)), (2, (1.0, 2.5)),
                                       (3, (2.5, 1.0, 1.0)), (3, (1.0, 0.5, 3.0))])
def test_every_element_of_a_subdivided_mesh_lies_in_its_bound(d, spacing):
    bounds = quality_bounds(d, spacing=spacing)
    stretched = quality_bounds(d, spacing=spacing, subdivide=False)
    for name, labels in cases(d):
        mesh = mesh_labels(labels, spacing=spacing)
        for metric, (lo, hi) in bounds.items():
            values = mesh.cell_data[metric]
            assert (values >= lo - 1e-9).all() and (values <= hi + 1e-9).all(), (name, metric)
    # far better than stretching, and within the default limit's bound (aspect 1.25:
    # 1.3754 in 3-D, 0.8004 in 2-D), which every subdivided lattice meets
    assert bounds["quality"][1] < stretched["quality"][1] - 0.1
    assert bounds["quality"][1] <= (1.37536 if d == 3 else 0.80040)


def test_a_bad_spacing_is_refused():
    with pytest.raises(ValueError, match="spacing"):
        quality_bounds(3, spacing=(1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="spacing"):
        quality_bounds(2, spacing=(1.0, 1.0, 1.0))
    assert np.isfinite(quality_bounds(3, spacing=(1.0, 1.0, 4.0))["quality"][1])
