"""A cohort of images segmented with one saved model on ``dask.distributed``.

One task per image (:func:`segment_one`, which is :func:`~._apply.apply_model`: the labels
equal a one-by-one ``swa-imesh segment --model`` run), submitted to a ``LocalCluster`` of
single-threaded worker processes or to an existing scheduler, each retried on failure.
Nothing of our own schedules: placement, retries and lost workers are the scheduler's.

Outputs are named after the inputs, in the input's format: ``scan01.npy`` ->
``OUTDIR/scan01_labels.npy``, ``a.nii.gz`` -> ``a_labels.nii.gz``, a Zarr store -> a
``_labels.zarr`` store; JPEG, which cannot hold labels exactly, gives PNG. With a mesh
suffix each task also meshes its labels (``OUTDIR/scan01_mesh.vtu``, in the image's
frame: its spacing, or a NIfTI image's world). With conductivities each task also runs
the steady k_eff simulation of its labels (``simulate`` of the labels file: what ``swa-imesh
simulate OUTDIR/scan01_labels.npy -k ...`` gives), k_eff per axis in its row.
"""

from __future__ import annotations

import glob
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path

from .._dask_connect import connect_dask, first_line, with_dask_parameters
from .._dask_logs import quiet_dask

__all__ = ["expand_inputs", "output_for", "mesh_for", "connect", "run_batch", "segment_one",
           "simulate_labels", "missing_folders", "quiet_dask", "CONNECT_SECONDS",
           "DETERMINISTIC"]

CONNECT_SECONDS = 5        # an address that does not answer fails after this
_GLOB = set("*?[")


def missing_folders(output) -> list[Path]:
    """The folders of `output` that do not exist yet, outermost first, once the nearest
    existing one is known to be a writable folder (one sentence otherwise).

    Examples
    --------
    >>> import tempfile
    >>> base = Path(tempfile.mkdtemp())
    >>> [p.relative_to(base).as_posix() for p in missing_folders(base / "a" / "b")]
    ['a', 'a/b']
    """
    import os

    path, missing = Path(output).absolute(), []
    while not os.path.lexists(path):
        missing.append(path)
        path = path.parent
    if not path.is_dir():
        raise NotADirectoryError(f"{path} is a file, not a folder; choose another output "
                                 "folder (-o).")
    if missing and not os.access(path, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot create {missing[0]} in folder {path}; choose "
                              "another output folder (-o).")
    return missing[::-1]


def _stem_suffix(path: Path) -> tuple[str, str]:
    name = path.name
    for long in (".ome.zarr", ".nii.gz"):
        if name.lower().endswith(long):
            return name[:-len(long)], long
    return path.stem, path.suffix


def output_for(path, outdir) -> Path:
    """``OUTDIR/<stem>_labels<suffix>`` in the input's format.

    Examples
    --------
    >>> [output_for(p, "out").name for p in ("scan01.npy", "b.nii.gz", "c.ome.zarr", "d.jpg")]
    ['scan01_labels.npy', 'b_labels.nii.gz', 'c_labels.zarr', 'd_labels.png']
    """
    stem, suffix = _stem_suffix(Path(path))
    suffix = {".ome.zarr": ".zarr", ".jpg": ".png", ".jpeg": ".png"}.get(suffix.lower(),
                                                                         suffix)
    return Path(outdir) / f"{stem}_labels{suffix}"


def mesh_for(path, outdir, suffix: str) -> Path:
    """``OUTDIR/<stem>_mesh<suffix>``.

    Examples
    --------
    >>> mesh_for("scan01.nii.gz", "out", ".vtu").name
    'scan01_mesh.vtu'
    """
    return Path(outdir) / f"{_stem_suffix(Path(path))[0]}_mesh{suffix}"


def expand_inputs(items: Sequence) -> list[Path]:
    """Image paths from files, Zarr stores, folders (their images) and glob patterns.

    Raises
    ------
    FileNotFoundError
        An item that names nothing, or a pattern or folder without images.
    ValueError
        Two inputs with the same stem (their outputs would collide).
    """
    from .._zarr_io import is_zarr
    from ..io import IMAGE_SUFFIXES, image_suffix

    found: list[Path] = []
    for item in map(str, items):
        p = Path(item)
        if _GLOB & set(item):
            hits = [Path(h) for h in sorted(glob.glob(item))]
        elif p.is_dir() and not is_zarr(p):
            hits = sorted(c for c in p.iterdir() if is_zarr(c) or (
                c.is_file() and image_suffix(c) in IMAGE_SUFFIXES))
        elif p.exists():
            hits = [p]
        else:
            raise FileNotFoundError(f"no image at {p}; check the path.")
        if not hits:
            raise FileNotFoundError(f"{item} holds no image ({', '.join(IMAGE_SUFFIXES)} "
                                    "or .zarr); check the folder or pattern.")
        found += hits
    stems: dict[str, Path] = {}
    for p in found:
        stem = _stem_suffix(p)[0]
        if stem in stems and stems[stem].resolve() != p.resolve():
            raise ValueError(f"{stems[stem]} and {p} would both write {stem}_labels; rename "
                             "one or run them in two batches.")
        stems[stem] = p
    return list(dict.fromkeys(p.resolve() for p in found))


@with_dask_parameters
def connect(scheduler: str | None = None, *, workers: int = 2,
            memory: int | str | None = None):
    """A ``distributed.Client``: on `scheduler`, else on a new ``LocalCluster``.

    Parameters
    ----------
    <connect_dask: scheduler, workers, memory>

    Returns
    -------
    distributed.Client
        On `scheduler`, or on the new local cluster.

    Raises
    ------
    ValueError
        When the scheduler does not answer within :data:`CONNECT_SECONDS`, or a local
        worker dies while starting.
    """
    # the parameters' entries are connect_dask's, filled in on import (one description)
    client, _ = connect_dask(scheduler, workers=workers, memory=memory,
                             timeout=CONNECT_SECONDS, preload=_load_package)
    return client


def _load_package() -> None:
    from ..segmentation import apply_model, load_model  # noqa: F401



#: errors a task raises the same way on every try (a corrupt image, a refusal; a full disk
#: too): reported in the image's row at once, not retried; anything else is retried
DETERMINISTIC = (ValueError, TypeError, KeyError, FileExistsError, FileNotFoundError,
                 IsADirectoryError, NotADirectoryError, PermissionError)


def segment_one(image: str, model_path: str, output: str, *, force: bool = False,
                memory: int | None = None, mesh: str | None = None,
                exclude: Sequence[int] = (), conductivity: dict | None = None) -> dict:
    """One task: :func:`~._apply.apply_model` of the model file on one image, chunked when
    a lone ``segment --model`` run would be (Zarr, or too big for `memory`), the chunks on
    this worker's own thread; then, with `mesh` (a mesh file path), the IMESH mesh of the
    labels (materials in `exclude` left out), written through ``mesh.write_mesh``; with
    `conductivity` (by label), the steady k_eff run of the labels (:func:`simulate_labels`).

    A try that finds an output already there without `force` (an earlier try of this
    task whose worker died after writing it; the batch checked that none existed)
    computes it again beside it and keeps the file when the contents are equal, else
    refuses. An error of :data:`DETERMINISTIC` comes back as ``{"error": sentence}``, so
    the scheduler does not retry it."""
    import errno

    try:
        return _segment_one(image, model_path, output, force=force, memory=memory,
                            mesh=mesh, exclude=exclude, conductivity=conductivity)
    except (*DETERMINISTIC, OSError) as exc:
        if not isinstance(exc, DETERMINISTIC) and exc.errno not in (errno.ENOSPC,
                                                                     errno.EDQUOT):
            raise               # may pass (a flaky network disk): the scheduler retries
        return {"image": image, "output": output, "error": f"{exc}"}


def _segment_one(image, model_path, output, *, force, memory, mesh, exclude,
                 conductivity) -> dict:
    from ..segmentation import apply_model, load_model, wants_chunks

    model = load_model(model_path)
    chunked = wants_chunks(image, output, model, budget=memory)
    row = _once(output, force, "labels", lambda path: apply_model(
        image, model, str(path), memory=memory, force=force, workers=1, chunked=chunked,
        scheduler="sync"))
    row["output"] = str(output)
    if mesh:
        row["mesh"] = _once(mesh, force, "mesh", lambda path: _mesh_labels_file(
            image, output, str(path), exclude=exclude, force=force))
        row["mesh"]["file"] = str(mesh)
    if conductivity:
        row["simulate"] = simulate_labels(output, conductivity, exclude=exclude)
    return row


def _once(target: str, force: bool, kind: str, write: Callable[[Path], dict]) -> dict:
    """``write(target)``, or, when `target` exists and `force` is false, ``write`` to a
    scratch path beside it and keep `target` if the two hold the same labels or mesh."""
    import os

    from .._atomic import scratch_folder

    target_p = Path(target)
    if force or not os.path.lexists(target_p):
        return write(target_p)
    with scratch_folder(target_p.parent) as folder:
        again = folder / target_p.name
        row = write(again)
        if not _same(kind, again, target_p):
            raise FileExistsError(
                f"{target_p} appeared while this batch ran and holds other {kind} than this "
                "image gives; remove it or choose another output folder.")
    return row


def _same(kind: str, a: Path, b: Path) -> bool:
    import numpy as np

    try:
        if kind == "labels":
            (la, sa), (lb, sb) = _read_labels(str(a)), _read_labels(str(b))
            return la.shape == lb.shape and np.array_equal(la, lb) and np.allclose(sa, sb)
        from ..mesh import read_mesh

        ma, mb = read_mesh(a), read_mesh(b)
        return all(np.array_equal(getattr(ma, k), getattr(mb, k))
                   for k in ("points", "cells", "material"))
    except (ValueError, OSError):       # a truncated or foreign file is not ours
        return False


def _read_labels(path: str):
    from .._zarr_io import is_zarr, open_lazy
    from ..io import read_image

    if is_zarr(path):
        lazy, spacing = open_lazy(path)
        return lazy.compute(), spacing
    return read_image(path)


def simulate_labels(path, conductivity: dict, *, exclude: Sequence[int] = ()) -> dict:
    """The k_eff run of ``swa-imesh simulate PATH -k ...`` (mixed protocol, P1, every
    axis) on a labels file, with its spacing; its JSON summary.

    `conductivity` maps labels to values; materials an image does not hold are dropped
    from it (a lone ``simulate`` run refuses a conductivity for an absent material, and a
    cohort's images need not all hold every material).
    """
    import numpy as np

    from ..simulate import simulate

    labels, spacing = _read_labels(str(path))
    present = set(np.unique(labels).tolist()) - set(exclude)
    result = simulate(labels, {k: v for k, v in conductivity.items() if int(k) in present},
                      spacing=spacing, exclude=tuple(exclude))
    return result.summary()


def _mesh_labels_file(image: str, labels_path: str, mesh_path: str, *, exclude,
                      force: bool) -> dict:
    """Mesh a written labels file (placed as the image: spacing, or a NIfTI affine)."""
    from ..io import read_affine
    from ..mesh import mesh_labels, write_mesh

    labels, spacing = _read_labels(labels_path)
    affine = read_affine(image)
    mesh = mesh_labels(labels, exclude=list(exclude), spacing=None if affine is not None
                       else spacing, affine=affine)
    write_mesh(mesh, mesh_path, force=force)
    return {"file": str(mesh_path), "points": int(len(mesh.points)),
            "cells": int(len(mesh.cells))}


def run_batch(images: Sequence, model_path, outdir, *, client, force: bool = False,
              memory: int | None = None, retries: int = 2, mesh: str | None = None,
              exclude: Sequence[int] = (), conductivity: dict | None = None,
              progress: Callable[[int, int, dict], None] | None = None) -> list[dict]:
    """Segment every image on the client's cluster; one row per image, in input order.

    Parameters
    ----------
    images : sequence of Path
        From :func:`expand_inputs`.
    model_path : str or Path
        The saved model (each worker loads it).
    outdir : str or Path
        An existing folder; outputs are :func:`output_for` each image.
    client : distributed.Client
    force : bool
        Replace existing outputs (without it they are refused before any work).
    memory : int, optional
        Budget of each task (chunked images).
    retries : int
        Times the scheduler retries a failed task.
    mesh : str, optional
        A mesh suffix (``.vtu``, ``.msh``, ...): also mesh each image's labels into
        ``OUTDIR/<stem>_mesh<suffix>`` (:func:`mesh_for`).
    exclude : sequence of int
        Materials the meshes and simulations leave out.
    conductivity : dict of int to float or list, optional
        Per label (see :func:`~napari_swa_imesh.simulate.simulate`): also run the steady
        k_eff simulation of each image's labels (:func:`simulate_labels`).
    progress : callable, optional
        Called as ``progress(done, total, row)`` when each image finishes.

    Returns
    -------
    list of dict
        :func:`~._apply.apply_model`'s summary per image, or ``image``, ``output`` and
        ``error`` (one sentence) for an image that failed every try.
    """
    from distributed import as_completed

    from ..io import check_writable

    outdir = Path(outdir)
    if not outdir.is_dir():
        raise FileNotFoundError(f"output folder {outdir} does not exist; create it first.")
    outputs = [output_for(p, outdir) for p in images]
    meshes = [mesh_for(p, outdir, mesh) if mesh else None for p in images]
    for out in outputs + [m for m in meshes if m]:
        check_writable(out, force=force)
    # keys name the image and are new each run: a scheduler keeps results of a key it
    # still holds, which would hand back an earlier run's row
    futures = {client.submit(segment_one, str(p), str(model_path), str(out), force=force,
                             memory=memory, mesh=None if m is None else str(m),
                             exclude=tuple(exclude), conductivity=conductivity,
                             retries=retries, pure=False,
                             key=f"segment-{Path(p).name}-{uuid.uuid4().hex[:12]}"): i
               for i, (p, out, m) in enumerate(zip(images, outputs, meshes))}
    rows: list[dict] = [{} for _ in outputs]        # every one filled as its task ends
    for done, fut in enumerate(as_completed(futures), 1):
        i = futures[fut]
        try:
            row = fut.result()
        except Exception as exc:  # the task's own sentence (bad image, full disk...)
            row = {"error": f"{exc}"}
        if "error" in row:
            row = {"image": str(images[i]), "output": str(outputs[i]),
                   "error": first_line(row["error"])}
        rows[i] = row
        if progress is not None:
            progress(done, len(outputs), row)
    return rows
