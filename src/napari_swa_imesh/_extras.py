"""Optional dependencies: which extra brings a module, and the check at the door.

The plain install (``pip install napari-swa-imesh``) holds what every user needs: read an
image, segment it in memory, mesh it, simulate, the napari widgets. One path needs more:

* ``[scale]`` (dask, distributed, zarr): chunked segmentation (Zarr images and outputs,
  ``--memory``, images too big for memory), Zarr stores and the ``batch`` command;
* ``[xdmf]`` (h5py): XDMF + HDF5 mesh files;
* ``[all]``: both.

:func:`require` is called where such a path starts, before any work, and raises
:class:`MissingExtra` (a ValueError and an ImportError: the command line exits 2 with the
sentence) naming the extra to install. Nothing is imported here at import time.
"""

from __future__ import annotations

import importlib

__all__ = ["EXTRAS", "MissingExtra", "has", "require"]

#: module -> the extra that brings it
EXTRAS = {"dask": "scale", "distributed": "scale", "zarr": "scale", "h5py": "xdmf"}


class MissingExtra(ImportError, ValueError):
    """A module of an optional extra is not installed; the message names the extra."""


def has(module: str) -> bool:
    """Whether `module` (a key of :data:`EXTRAS`) can be imported."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def require(*modules: str, purpose: str, alternative: str | None = None) -> None:
    """Raise :class:`MissingExtra` unless every one of `modules` can be imported.

    Parameters
    ----------
    *modules : str
        Keys of :data:`EXTRAS`, e.g. ``"dask", "zarr"``.
    purpose : str
        What needs them, as the start of a sentence ("segmenting chunk by chunk").
    alternative : str, optional
        What to do instead, ending the sentence ("or choose .vtu").

    Examples
    --------
    >>> require("dask", purpose="segmenting chunk by chunk")   # installed: no error
    """
    for module in modules:
        if not has(module):
            extra = EXTRAS[module]
            instead = f", {alternative}" if alternative else ""
            raise MissingExtra(
                f"{purpose} needs {module}, which is not installed; install it with "
                f'pip install "napari-swa-imesh[{extra}]"{instead}.', name=module)
