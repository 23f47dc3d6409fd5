"""napari-swa-imesh: from a biological image to a finite-element mesh.

SWA segments a 2-D or 3-D image at its representative elementary scale; IMESH turns the
label image into a conforming, quality-guaranteed triangle or tetrahedral mesh. Compute
lives in :mod:`napari_swa_imesh.segmentation` and :mod:`napari_swa_imesh.mesh`; nothing
imported here loads napari or Qt.
"""

from .io import read_image, write_labels

__version__ = "0.1.0"

__all__ = ["RegionTree", "build_tree", "read_image", "write_labels", "__version__"]

#: names loaded on first use: the region tree is the mesher's (``mesh/mesher/_tree.py``), and
#: importing the package (or segmentation) must not import the mesher
_LAZY = {"RegionTree": ".mesh", "build_tree": ".mesh"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
