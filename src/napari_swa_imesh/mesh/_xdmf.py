"""XDMF 3 with its arrays in an HDF5 ``.h5`` beside it (same stem), through meshio.

meshio's XDMF support needs h5py, an optional package: without it, reading or writing
``.xdmf`` is refused with one sentence saying what to install or choose instead. The
``.h5`` is the second target of an ``.xdmf`` write (both land atomically together); the
``.xdmf`` names it by the temporary's name, which is the target's (see ``io.atomic_write``).
"""

from __future__ import annotations

__all__ = ["require_h5py", "write_xdmf"]


def require_h5py(verb: str) -> None:
    """Raise ValueError (what to install, what to choose) when h5py is missing."""
    try:
        import h5py  # noqa: F401
    except ImportError:
        raise ValueError(
            f"cannot {verb} .xdmf: meshio's XDMF support needs the h5py package, which is "
            "not installed; `pip install h5py`, or choose .vtu."
        ) from None


def write_xdmf(m, path: str) -> None:
    """Write the meshio mesh `m` as ``path`` (.xdmf) and its ``.h5`` twin."""
    import meshio

    require_h5py("write")
    meshio.write(path, m, file_format="xdmf", data_format="HDF")
