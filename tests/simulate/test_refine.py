"""Interface refinement on a problem with an exact answer: the checkerboard.

A square n x n checkerboard (n even) of conductivities k1 and k2 under the mixed-boundary
protocol has k_eff = sqrt(k1 k2) exactly (Keller's reciprocal theorem: a 90 degree turn
maps the board onto its complement). The field is singular at every corner where four
squares meet, so P1 converges slowly there: refinement at the interfaces must bring the
error down level by level.
"""

from __future__ import annotations

import numpy as np
import pytest
from simulate_cases import checkerboard

from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import simulate


def test_refinement_converges_to_the_exact_checkerboard_conductivity():
    lab = checkerboard(4, 4)
    exact = np.sqrt(10.0)
    errors, dofs = [], []
    for refine in (1, 2, 3):
        r = simulate(lab, {1: 1.0, 2: 10.0}, axes="x", refine=refine, interval=False)
        errors.append(r.k_eff["x"] / exact - 1)
        dofs.append(r.dofs)
    assert all(e > 0 for e in errors)            # conforming P1: from above
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.04
    assert dofs[0] < dofs[1] < dofs[2]


def test_refine_on_a_mesh_is_refused():
    mesh = mesh_labels(checkerboard(2, 2))
    with pytest.raises(ValueError, match="refine apply to a label image"):
        simulate(mesh, {1: 1.0, 2: 2.0}, refine=1)
