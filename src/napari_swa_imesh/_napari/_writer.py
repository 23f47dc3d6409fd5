"""npe2 writer: File > Save Selected Layer(s) on a mesh Surface writes the real mesh.

A Surface layer carries only triangles; the mesh widget keeps the real mesh (tetrahedra in
3-D, materials, quality) in the layer's metadata, and this writer writes that, in the
format the suffix names (every format of :func:`napari_swa_imesh.mesh.write_mesh`).
"""

from __future__ import annotations

from typing import Any

from ._layers import MESH_KEY

__all__ = ["write_mesh_layer", "mesh_of_attributes"]


def mesh_of_attributes(attributes: dict):
    """The Mesh kept in a Surface layer's metadata, or a ValueError saying what to do."""
    mesh = (attributes.get("metadata") or {}).get(MESH_KEY)
    if mesh is None:
        raise ValueError(
            f"the Surface layer {attributes.get('name', '')!r} holds no IMESH mesh; mesh a "
            "Labels layer in the SWA-IMESH mesh widget and save the layer it creates.")
    return mesh


def write_mesh_layer(path: str, data: Any, attributes: dict) -> list[str]:
    """Write the mesh of a Surface layer made by the mesh widget.

    Parameters
    ----------
    path : str
        Target file; its suffix picks the format (.vtu, .vtk, .msh, .xdmf, .inp,
        .node/.ele). napari's save dialog has already asked before replacing a file.
    data : tuple
        The Surface data (unused: it holds only the drawn triangles).
    attributes : dict
        Layer attributes; ``metadata`` holds the mesh.

    Returns
    -------
    list of str
        Every file written.
    """
    from ..mesh import write_mesh

    mesh = mesh_of_attributes(attributes)
    return [str(p) for p in write_mesh(mesh, path, force=True)]
