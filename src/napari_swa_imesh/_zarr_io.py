"""Images larger than memory: Zarr stores and memory-mapped ``.npy`` as Dask arrays.

Read (nothing is loaded until a chunk is computed):

* a **Zarr array** (format 2 or 3, read with ``zarr``); its ``spacing`` attribute, when
  present, is the voxel spacing (this package writes it);
* an **OME-Zarr image** (a group with ``multiscales`` metadata, NGFF 0.4 in the group's
  attributes or 0.5 under ``ome``): every resolution level, axes of length 1 that are not
  space (``c``, ``t``) dropped, the spacing of level 0 from its ``scale`` transform;
* a **``.npy`` file**, memory-mapped block by block (each block's mapping is closed once
  it is copied, so the pages read do not pile up in the process);
* any other image :func:`~napari_swa_imesh.io.read_image` reads, loaded and wrapped.

Written: a label store by :func:`write_zarr_to`, chunk by chunk from a Dask array, into a
temporary path that :func:`~napari_swa_imesh.io.atomic_write` moves into place.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._extras import has, require

__all__ = ["is_zarr", "is_lazy", "open_lazy", "open_levels", "write_zarr_to",
           "SPACING_KEY"]

SPACING_KEY = "spacing"        # attribute of the arrays this package writes
_MARKERS = ("zarr.json", ".zarray", ".zgroup")


def is_zarr(path) -> bool:
    """Whether `path` names a Zarr store (a ``.zarr`` name, or a folder with Zarr metadata)."""
    p = Path(path)
    return p.name.lower().endswith(".zarr") or (
        p.is_dir() and any((p / m).is_file() for m in _MARKERS))


def is_lazy(path) -> bool:
    """Whether `path` is read lazily rather than loaded whole: a ``.zarr`` store, or a
    ``.npy`` when dask is installed (without the ``[scale]`` extra it is loaded whole).
    """
    name = Path(path).name.lower()
    return name.endswith(".zarr") or (name.endswith(".npy") and has("dask"))


def _open_node(p: Path):
    require("zarr", purpose=f"reading the Zarr store {p.name}")
    import zarr

    if not p.exists():
        raise FileNotFoundError(f"no Zarr store at {p}; check the path.")
    try:
        return zarr.open(store=str(p), mode="r")
    except Exception as exc:  # missing metadata, bad JSON, unknown codec...
        raise ValueError(f"cannot open {p} as a Zarr store ({type(exc).__name__}: {exc}); "
                         "give a Zarr array or an OME-Zarr image.") from exc


def _multiscales(attrs: dict) -> list | None:
    ome = attrs.get("ome")
    found = attrs.get("multiscales") or (ome.get("multiscales") if isinstance(ome, dict)
                                         else None)
    return found if isinstance(found, list) and found else None


def open_levels(path, *, chunks=None):
    """Every resolution level of a Zarr store as a Dask array, and the spacing of level 0.

    Parameters
    ----------
    path : str or Path
        A Zarr array, or an OME-Zarr image (a group with ``multiscales`` metadata).
    chunks : tuple of int, optional
        Dask chunks of level 0 (default: the store's own chunks).

    Returns
    -------
    levels : list of dask.array.Array
        Full resolution first; one for a plain array.
    spacing : tuple of float
        Voxel size per axis of level 0 (1.0 where the store says nothing).

    Raises
    ------
    FileNotFoundError
        Nothing at `path`.
    ValueError
        Not a Zarr store, a group that is not an OME-Zarr image, or an image with more
        than one channel or time point.
    """
    require("dask", "zarr", purpose="reading or writing a Zarr store")
    import zarr

    p = Path(path)
    node = _open_node(p)
    if isinstance(node, zarr.Array):
        spacing = node.attrs.get(SPACING_KEY)
        arr = _from_zarr(node, p, chunks if chunks is not None else node.chunks)
        ok = isinstance(spacing, list) and len(spacing) == arr.ndim
        return [arr], tuple(float(s) for s in spacing) if ok else (1.0,) * arr.ndim
    multi = _multiscales(dict(node.attrs))
    if multi is None:
        arrays = sorted(k for k, _ in node.arrays())
        inside = f" (it holds the array(s) {', '.join(arrays)}: give {p / arrays[0]})" \
            if arrays else ""
        raise ValueError(f"{p} is a Zarr group, not an array or an OME-Zarr image (no "
                         f"'multiscales' metadata){inside}.")
    meta = multi[0]
    axes = [a if isinstance(a, dict) else {"name": a} for a in meta.get("axes", [])]
    levels, spacing = [], None
    for i, ds in enumerate(meta["datasets"]):
        z = node[ds["path"]]
        names = axes if len(axes) == z.ndim else [{"name": "x"}] * z.ndim
        space = [a.get("type", "space" if a["name"] in "zyx" else "") == "space"
                 for a in names]
        extra = [n for n, s, a in zip(z.shape, space, names) if not s and n != 1]
        if extra:
            raise ValueError(f"{p} holds {extra} channels or time points (axes "
                             f"{[a['name'] for a in names]}); give an image of one channel "
                             "and one time point.")
        c = chunks if (i == 0 and chunks is not None) else None
        arr = _from_zarr(z, p, z.chunks if c is None else tuple(
            c[sum(space[:k])] if s else 1 for k, s in enumerate(space)))
        arr = arr[tuple(slice(None) if s else 0 for s in space)]
        levels.append(arr)
        if i == 0:
            scale = [t.get("scale") for t in ds.get("coordinateTransformations", [])
                     if t.get("type") == "scale"]
            if scale and len(scale[0]) == len(space):
                spacing = tuple(float(v) for v, s in zip(scale[0], space) if s)
    return levels, spacing or (1.0,) * levels[0].ndim


def _from_zarr(z, store: Path, chunks):
    """`z` as a Dask array whose every read says which chunk of `store` is damaged."""
    import dask.array as da

    return da.from_array(_CheckedChunks(z, store), chunks=chunks, asarray=True, fancy=False,
                         name=f"zarr-{store.name}-{z.path}-{id(z):x}")


class _CheckedChunks:
    """A Zarr array read block by block; a chunk that cannot be read or decoded (a
    truncated or corrupt file: zstd or blosc errors, wrong sizes) is reported as a
    ValueError naming the chunk and the store, not as the codec's own error."""

    def __init__(self, z, store: Path):
        self.z, self.store = z, store
        self.shape, self.dtype, self.ndim = z.shape, z.dtype, z.ndim

    def __getitem__(self, index):
        try:
            return self.z[index]
        except Exception as exc:  # a codec error; find which chunk of the block it is
            raise ValueError(self._damaged(index, exc)) from exc

    def _damaged(self, index, exc) -> str:
        grid = [range(s.start // c, -(-s.stop // c)) if isinstance(s, slice) else
                range(s // c, s // c + 1) for s, c in zip(index, self.z.chunks)]
        bad = []
        for key in np.stack(np.meshgrid(*grid, indexing="ij"), -1).reshape(-1, len(grid)):
            sl = tuple(slice(k * c, (k + 1) * c) for k, c in zip(key, self.z.chunks))
            try:
                self.z[sl]
            except Exception:
                bad.append(tuple(int(k) for k in key))
        where = f"chunk {bad[0]}" if len(bad) == 1 else (
            f"chunks {', '.join(map(str, bad))}" if bad else "a chunk")
        array = f" (array {self.z.path})" if self.z.path else ""
        return (f"{where} of the Zarr store {self.store}{array} cannot be read "
                f"({type(exc).__name__}: {exc}): the file is truncated or damaged; restore "
                "the store from a copy or write it again.")


class _NpyBlocks:
    """A ``.npy`` file as an indexable array whose every read maps, copies and unmaps."""

    def __init__(self, path: Path):
        from ._headers import load_npy

        mm = load_npy(path, mmap_mode="r")
        if not isinstance(mm, np.memmap):  # pragma: no cover - mmap_mode="r" maps a .npy
            raise TypeError(f"{path} did not open as a memory map")
        self.path, self.shape, self.dtype, self.ndim = path, mm.shape, mm.dtype, mm.ndim
        self.offset, self.order = mm.offset, "F" if mm.flags.f_contiguous and mm.ndim > 1 \
            else "C"
        del mm

    def __getitem__(self, index):
        mm = np.memmap(self.path, self.dtype, "r", self.offset, self.shape, self.order)
        out = np.array(mm[index])
        del mm                                  # unmaps: the pages read leave the process
        return out


def open_lazy(path, *, chunks=None):
    """An image as a Dask array without loading it, and its voxel spacing.

    Parameters
    ----------
    path : str or Path
        Zarr (array or OME-Zarr image, level 0), ``.npy`` (memory-mapped), or any file
        :func:`~napari_swa_imesh.io.read_image` reads (loaded whole).
    chunks : tuple of int, optional
        Dask chunks (default: the store's, or the whole image for other files).

    Returns
    -------
    image : dask.array.Array
    spacing : tuple of float

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`open_levels` and :func:`~napari_swa_imesh.io.read_image`.
    """
    require("dask", purpose="opening an image without loading it (chunked work)")
    import dask.array as da

    p = Path(path)
    if is_zarr(p):
        levels, spacing = open_levels(p, chunks=chunks)
        return levels[0], spacing
    if p.name.lower().endswith(".npy"):
        if not p.is_file():
            raise FileNotFoundError(f"no image file at {p}; check the path.")
        from ._headers import Refused

        try:
            blocks = _NpyBlocks(p)
        except Refused:            # not a .npy file, or one of objects: said in full
            raise
        except Exception as exc:   # a damaged file
            raise ValueError(f"cannot read {p} as a .npy image: {exc}") from exc
        return (da.from_array(blocks, chunks=chunks or blocks.shape, asarray=True,
                              fancy=False), (1.0,) * blocks.ndim)
    from .io import read_image

    image, spacing = read_image(p)
    return da.from_array(image, chunks=chunks or image.shape), spacing


def write_zarr_to(tmp, data, *, spacing=None, **compute) -> None:
    """Compute the Dask array `data` chunk by chunk into a new Zarr array at `tmp`.

    Each computed chunk is written and released (nothing holds the whole array). The
    store's chunks are `data`'s first chunk shape, so every Dask chunk is whole Zarr chunks.

    Parameters
    ----------
    tmp : Path
        A temporary path from :func:`~napari_swa_imesh.io.atomic_write` (nothing there).
    data : dask.array.Array
    spacing : sequence of float, optional
        Written as the ``spacing`` attribute (read back by :func:`open_lazy`).
    **compute
        Passed to ``dask.array.store`` (``scheduler``, ``num_workers``...).
    """
    require("dask", "zarr", purpose="reading or writing a Zarr store")
    import dask.array as da
    import zarr

    attrs: dict[str, Any] = {} if spacing is None else {SPACING_KEY: [float(s) for s in spacing]}
    # dask types its targets as numpy array-likes; a zarr array (anything that takes
    # slice assignment) is one to dask.array.store
    z: Any = zarr.create_array(store=str(tmp), shape=data.shape, dtype=data.dtype,
                          chunks=tuple(c[0] for c in data.chunks), attributes=attrs)
    da.store(data, z, lock=False, **compute)
