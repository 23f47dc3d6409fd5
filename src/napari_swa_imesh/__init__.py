"""napari-swa-imesh: from a biological image to a finite-element mesh.

SWA segments a 2-D or 3-D image at its representative elementary scale; IMESH turns the
label image into a conforming, quality-guaranteed triangle or tetrahedral mesh. Compute
lives in :mod:`napari_swa_imesh.segmentation` and :mod:`napari_swa_imesh.mesh`; nothing
imported here loads napari or Qt.
"""

from ._tree import RegionTree, build_tree
from .io import read_image, write_labels

__version__ = "0.1.0"

__all__ = ["RegionTree", "build_tree", "read_image", "write_labels", "__version__"]
