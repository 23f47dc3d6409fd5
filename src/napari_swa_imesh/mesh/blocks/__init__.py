"""Block-wise meshing of label volumes on Dask, conforming across blocks (issue 27).

* :func:`mesh_blocks`: a label volume (Zarr, ``.npy`` or array) meshed block by block into
  a partitioned mesh, ``OUT.pvtu`` (VTK pieces) or ``OUT.xdmf`` (HDF5 pieces), with the
  folder ``OUT/`` of pieces; every check of the whole passes or nothing is written;
* :func:`read_pvtu` (also through ``mesh.read_mesh``): the pieces of a ``.pvtu`` or an
  XDMF index (:func:`is_xdmf_index`) joined into one
  :class:`~napari_swa_imesh.mesh.Mesh` where it fits in memory; :func:`read_pvtu_groups`:
  their facet groups by global vertex ids;
* :func:`choose_block`, :func:`block_memory`: the block side a worker's memory allows.

``_core`` holds the numerics (block plan, coarse balance, one block's mesh, seams),
``_files`` the file layout, ``_run`` the rounds of tasks, ``_cli`` the command-line path.
"""

from ._files import is_xdmf_index, read_pvtu, read_pvtu_groups
from ._run import (
    BLOCK_SUFFIXES,
    BlockMeshError,
    block_memory,
    choose_block,
    mesh_blocks,
)

__all__ = [
    "BLOCK_SUFFIXES",
    "BlockMeshError",
    "block_memory",
    "choose_block",
    "is_xdmf_index",
    "mesh_blocks",
    "read_pvtu",
    "read_pvtu_groups",
]
