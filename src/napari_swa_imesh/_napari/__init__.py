"""The napari plugin: widgets, workers, sample data, reader and writer.

Everything here only adapts :mod:`napari_swa_imesh.segmentation` and
:mod:`napari_swa_imesh.mesh`; no numerics live in this package, and nothing outside it
imports napari, Qt or magicgui.
"""
