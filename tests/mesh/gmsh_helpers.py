"""What Gmsh itself reads from a ``.msh`` file, for the tests of the Gmsh writer (not a
test module); skips the calling test when the optional gmsh package is missing."""

from __future__ import annotations

import numpy as np
import pytest


def gmsh_reads(path, ndim: int) -> tuple[dict[str, tuple[int, int]], np.ndarray]:
    """Physical name -> (tag, element count) of the `ndim`-dimensional groups, and the
    elements' signed inverse condition numbers (``minSICN``: negative when inverted)."""
    gmsh = pytest.importorskip("gmsh", reason="the gmsh package is optional (pip install gmsh)")
    gmsh.initialize(["", "-v", "0"])
    try:
        gmsh.open(str(path))
        groups = {}
        for dim, tag in gmsh.model.getPhysicalGroups(ndim):
            entities = gmsh.model.getEntitiesForPhysicalGroup(dim, tag)
            count = sum(len(gmsh.model.mesh.getElements(dim, e)[1][0]) for e in entities)
            groups[gmsh.model.getPhysicalName(dim, tag)] = (tag, count)
        _, tags, _ = gmsh.model.mesh.getElements(ndim)
        quality = gmsh.model.mesh.getElementQualities(np.concatenate(tags), "minSICN")
    finally:
        gmsh.finalize()
    return groups, np.asarray(quality)
