"""The mesh as a value: the :class:`~napari_swa_imesh.mesh.Mesh` type, element quality and
its proven bounds, the memory model and the world frame. Public names are exported by
:mod:`napari_swa_imesh.mesh`.
"""
