"""Mesh files: the writers' shared conventions and preparation, one module per format
(VTU and its facet companion, Gmsh, Abaqus, XDMF, Triangle/TetGen, text numbers), order
2 nodes, reading and the PyVista bridge. Public names are exported by
:mod:`napari_swa_imesh.mesh`.
"""
