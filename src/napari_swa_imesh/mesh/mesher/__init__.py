"""Building a mesh: the region tree, 2:1 balance, the lattice and its subdivision, the
template tables and cutting, the Delaunay reference, coarsening, adaptive refinement and
the mesher's door (``_imesh``). Public names are exported by :mod:`napari_swa_imesh.mesh`.
"""
