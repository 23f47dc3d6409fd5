"""The check's facet keys built as a linear form of the sorted ids (one pass) are the
keys the shift-and-OR packing gives (several passes), facet by facet and side by side."""

import numpy as np
import pytest

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.mesh.checks import _facets


def _decoded(passes, d):
    rows = np.concatenate([np.stack(packer.decode(keys, d) + [keys & 1], axis=1)
                           for keys, packer in passes])
    return rows[np.lexsort(rows.T[::-1])]


@pytest.mark.parametrize("shape", [(13, 17), (7, 6, 9)])
def test_linear_keys_are_the_packed_keys(shape):
    rng = np.random.default_rng(len(shape))
    mesh = mesh_labels(rng.integers(0, 3, shape))
    d, m = mesh.ndim, mesh.n_cells
    sign = rng.choice(np.array([-1, 0, 1], np.int8), m)   # every side bit exercised
    w = _facets._spread_bits(mesh.cells)
    one = list(_facets._side_passes(mesh.cells, sign, w))
    several = list(_facets._side_passes(mesh.cells, sign, w, max_keys=m * (d + 1) // 3))
    assert len(one) == 1 and len(several) > 1
    assert np.all(np.diff(one[0][0]) >= 0)                  # sorted
    assert np.array_equal(_decoded(one, d), _decoded(several, d))
