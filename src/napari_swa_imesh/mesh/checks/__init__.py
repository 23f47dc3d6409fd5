"""What a mesh is checked and looked at by: the mesh checks and the chain check, facets
and facet groups, the shown surface and the clip. Public names are exported by
:mod:`napari_swa_imesh.mesh`.
"""
