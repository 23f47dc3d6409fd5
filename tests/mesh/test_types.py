"""A Mesh checks its arrays when built; the mesher's trusted path skips nothing it needs."""

import dataclasses

import numpy as np
import pytest

from napari_swa_imesh.mesh.mesher._imesh import mesh_labels
from napari_swa_imesh.mesh.model._types import Mesh

POINTS = np.array([[0.0, 0], [1, 0], [0, 1]])


def test_arrays_are_normalised_without_copying_what_fits():
    points, cells, material = POINTS.copy(), np.array([[0, 1, 2]], np.intp), np.array([3])
    mesh = Mesh(points, cells, material.astype(np.int64))
    assert mesh.points is points and mesh.cells is cells
    mesh = Mesh(points.astype(np.float32), cells.astype(np.int32), material.astype(np.uint8))
    assert (mesh.points.dtype, mesh.cells.dtype, mesh.material.dtype) == \
        (np.float64, np.intp, np.int64)


@pytest.mark.parametrize("change,error,match", [
    ({"points": np.zeros((3, 4))}, ValueError, r"shape \(N, 2\) or \(N, 3\); got \(3, 4\)"),
    ({"points": POINTS * np.nan}, ValueError, "3 mesh point.*NaN or infinite"),
    ({"points": np.array([["a", "b"]] * 3)}, TypeError, "real numbers"),
    ({"cells": np.array([[0, 1, 3]])}, ValueError, "vertices 0..3, but the mesh has 3 points"),
    ({"cells": np.array([[0, 1, -1]])}, ValueError, "vertices -1..1"),
    ({"cells": np.array([[0, 1, 2, 2]])}, ValueError, "need 3 corners each"),
    ({"cells": np.array([[0.0, 1, 2]])}, TypeError, "integer vertex ids"),
    ({"material": np.array([1, 2])}, ValueError, r"one id per element \(1\)"),
    ({"material": np.array([1.5])}, TypeError, "material must hold integer ids"),
    ({"cell_data": {"quality": np.ones(2)}}, ValueError,
     r"cell_data\['quality'\] must hold one value"),
    ({"spacing": (1.0, 1.0, 1.0)}, ValueError, "spacing must be empty or hold 2 values"),
])
def test_bad_arrays_are_refused(change, error, match):
    args = {"points": POINTS, "cells": np.array([[0, 1, 2]]), "material": np.array([1])}
    args.update(change)
    with pytest.raises(error, match=match):
        Mesh(**args)


def test_the_mesher_builds_a_mesh_that_passes_its_own_validation():
    mesh = mesh_labels(np.array([[1, 1, 2], [1, 2, 2]]), spacing=0.5)
    again = dataclasses.replace(mesh)  # runs __post_init__ on the trusted arrays
    for name in ("points", "cells", "material"):
        assert getattr(again, name) is getattr(mesh, name)
    assert again.cell_data.keys() == mesh.cell_data.keys()
