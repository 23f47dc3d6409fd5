"""Block-wise meshing of a label volume on Dask: :func:`mesh_blocks`.

Two rounds of tasks, one per block each (``_blocks`` holds the numerics):

1. read the block and a one-voxel halo, return its mixed grids and voxel counts;
2. after the one global balance of the coarse grids (here, in the calling process: about
   ``N / 4`` bytes for ``N`` voxels), read the block again, mesh it, write its piece into
   the output's temporary folder and return a summary (counts, exact volumes, worst
   quality, the facets on its faces).

Then the checks of the whole: every shared face seen alike from both sides (the seam
check), total and per-material volumes equal to the voxel counts (integers, exact),
worst quality within the proven bound, every piece's own checks clean. Only then is the
index written and everything published by the atomic writer; on any failure nothing is
left. Tasks are retried by the scheduler (``retries``); a local cluster of single-threaded
worker processes is started unless a scheduler address or a client is given.
"""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..._dask_connect import connect_dask
from ..formats._registry import PARTITIONED, PVTU, XDMF_INDEX
from . import _core as bk
from . import _files as bf
from . import _periodic
from ._coarsen import coarsened, read_slices
from ._quadratic import n_global_ids
from ._refine import interface_cells
from ._timing import task_report, timed

__all__ = ["BLOCK_SUFFIXES", "BlockMeshError", "block_memory", "choose_block", "mesh_blocks"]

BLOCK_SUFFIXES = tuple(PARTITIONED)


class BlockMeshError(ValueError):
    """A check of the block-wise mesh failed: nothing was written."""


def block_memory(block: int, d: int = 3, order: int = 1) -> int:
    """Peak bytes of one meshing task of a cube of `block` voxels (conservative): the
    in-memory mesher's estimate for the block at the worst case, plus the local corner
    lattice (up to ``4 * block + 1`` points per axis, 10 bytes each); at `order` 2 the
    mid-edge nodes (edge keys, ids and the wider cells: 128 bytes for each of the
    ``d!`` elements a voxel may hold at worst)."""
    from ..model._memory import estimate_mesh_memory

    return int(estimate_mesh_memory((block,) * d, np.int64, check=False)
               + 10 * (4 * block + 1) ** d
               + (128 * math.factorial(d) * block ** d if order == 2 else 0))


def choose_block(shape, memory: int | None, block: int | None = None,
                 order: int = 1) -> int:
    """The block side: `block` if given (checked against `memory`), else the largest
    power of two, at most the default root, whose task fits `memory` (default 2 GB).

    Raises ValueError when even a block of 8 voxels does not fit.
    """
    d = len(shape)
    budget = memory if memory else 2 << 30
    cap = 1 << bk.default_top(shape)
    if block is not None:
        need = block_memory(int(block), d, order)
        if memory and need > memory:
            raise ValueError(f"a block of {block} voxels needs about {need / 2**30:.2f} GB "
                             f"per worker, above --memory {memory / 2**30:.2f} GB; give a "
                             "smaller --block or more --memory.")
        return int(block)
    b = max(2, cap)
    while b > 8 and block_memory(b, d, order) > budget:
        b //= 2
    if block_memory(b, d, order) > budget:
        raise ValueError(f"even a block of {b} voxels needs about "
                         f"{block_memory(b, d, order) / 2**30:.2f} GB per worker, above the "
                         f"{budget / 2**30:.2f} GB allowed; give more --memory.")
    return b


# ----------------------------------------------------------------------------- tasks
def _read(source, plan: bk.BlockPlan, index, raw: list | None = None) -> np.ndarray:
    """The block's window on the lattice: its voxels from a path (opened here, on the
    worker) or the array slice the caller handed over (``read_slices``), coarsened when
    asked (the labels before the vote appended to `raw`), repeated by the plan's
    factors."""
    slices, crop = read_slices(plan, index)
    if not isinstance(source, np.ndarray):
        from ..._zarr_io import open_lazy

        image, _ = open_lazy(source)
        source = np.asarray(image[slices].compute(scheduler="sync"))
    if crop is not None:
        _check_labels(source, index)                  # before the vote, which trusts them
        if source.dtype.kind == "f":
            source = source.astype(np.int64)          # whole numbers (checked)
        if raw is not None:
            raw.append(np.unique(source))
        source = coarsened(source, plan, crop)
    return plan.to_lattice(source, index)


def _check_labels(data: np.ndarray, index) -> None:
    if data.dtype.kind not in "iub":
        whole = np.isfinite(data).all() and np.array_equal(data, np.round(data))
        if not whole:
            raise ValueError(f"block {tuple(index)} holds non-integer labels; give a label "
                             "image (whole numbers >= 0).")
    if data.size and data.min() < 0:
        raise ValueError(f"block {tuple(index)} holds negative labels; labels are >= 0.")


def coarse_task(source, plan: bk.BlockPlan, index, interfaces=None):
    """Round 1: (mixed grids, (labels, counts) of the block's own lattice cells); with
    `interfaces` (the excluded materials, for ``refine``) a cell with an interface face
    on its boundary counts as mixed (``_refine``)."""
    raw: list = []
    data = _read(source, plan, index, raw)
    _check_labels(data, index)
    win = bk._window_labels(plan, index, data)
    core = win[(slice(1, -1),) * win.ndim]
    values, counts = np.unique(core[core >= 0], return_counts=True)
    mixed = bk.mixed_grids(win, plan.top)
    if interfaces is not None:
        mixed = [m | t for m, t in zip(mixed, interface_cells(win, plan.top, interfaces))]
    return mixed, (values, counts, raw[0] if raw else values)


def mesh_task(source, plan: bk.BlockPlan, index, grids, number: int, folder: str,
              output: str, options: dict) -> dict:
    """Round 2: mesh block `index`, write its piece (when it has elements) into `folder`
    and return its summary."""
    data = _read(source, plan, index)
    piece = bk.mesh_block(plan, index, data, grids, exclude=options["exclude"],
                          present=options["present"], material_names_=options["names"],
                          spacing=options["spacing"])
    summary = {"index": tuple(index), "number": number, "n_points": len(piece.points),
               "n_cells": len(piece.cells), "volumes": piece.volumes,
               "worst": float(piece.quality.max(initial=0.0)), "seams": piece.seams,
               "problems": piece.problems,
               "box": _periodic.box_facets(piece, plan.shape) if plan.periodic else {},
               "groups": {n: len(o) for n, (_, o) in piece.groups.items()}}
    if len(piece.cells):
        write = bf.write_piece_h5 if options["kind"] == XDMF_INDEX else bf.write_piece_vtu
        summary["n_points"] = write(Path(folder), output, number, piece, options["spacing"],
                                    options["group_ids"], np.dtype(options["ids"]),
                                    np.dtype(options["mat"]), options["order"], plan.shape)
    return summary


# ----------------------------------------------------------------------------- running
class _Local:
    """Runs tasks in this process, one after the other, retrying each (``workers=0``)."""

    def map(self, fn, args_list, retries, progress, label):
        out = []
        for i, args in enumerate(args_list, 1):
            for attempt in range(retries + 1):
                try:
                    out.append(fn(*args))
                    break
                except (ValueError, TypeError, FileNotFoundError):
                    raise
                except Exception:
                    if attempt == retries:
                        raise
            if progress:
                progress(label, i, len(args_list))
        return out


class _Dask:
    """Runs tasks on a ``distributed.Client``; results in submission order."""

    def __init__(self, client):
        self.client = client

    def map(self, fn, args_list, retries, progress, label):
        from distributed import as_completed

        run = uuid.uuid4().hex[:10]
        futures = [self.client.submit(fn, *args, retries=retries, pure=False,
                                      key=f"{label}-{i}-{run}")
                   for i, args in enumerate(args_list)]
        position = {f.key: i for i, f in enumerate(futures)}
        out: list = [None] * len(futures)
        try:
            for done, fut in enumerate(as_completed(futures), 1):
                out[position[fut.key]] = fut.result()
                if progress:
                    progress(label, done, len(futures))
        except BaseException:
            for f in futures:
                f.cancel()
            raise
        return out


def _open_source(labels):
    """(source handed to tasks, shape, spacing, dtype): a path stays a path."""
    from ..._validation import as_labels

    if isinstance(labels, (str, Path)):
        from ..._zarr_io import open_lazy

        image, spacing = open_lazy(labels)
        if image.ndim not in (2, 3):
            raise ValueError(f"{labels} is {image.ndim}-D; block-wise meshing takes a 2-D "
                             "or 3-D label image.")
        return str(labels), tuple(image.shape), tuple(spacing), image.dtype
    lab = as_labels(labels, min_ndim=2, max_ndim=3)
    return lab, lab.shape, (1.0,) * lab.ndim, lab.dtype


def mesh_blocks(labels, output, *, block: int | None = None, memory: int | None = None,
                workers: int = 2, scheduler: str | None = None, client=None,
                exclude=(), spacing=None, material_names: dict | None = None,
                subdivide: bool = True, max_aspect: float | None = None,
                max_size: float | None = None, refine: int = 0, order: int = 1,
                periodic: bool = False, coarsen: int = 0,
                force: bool = False, retries: int = 2,
                progress: Callable[[str, int, int], None] | None = None) -> dict:
    """Mesh a label volume block by block into a partitioned mesh (``.pvtu`` or ``.xdmf``).

    Parameters
    ----------
    labels : str, Path or (M, N[, P]) array_like of int
        A Zarr store or ``.npy`` file (read block by block on the workers), or an array.
    output : str or Path
        ``OUT.pvtu`` (VTK pieces) or ``OUT.xdmf`` (HDF5 pieces); the pieces go in the
        folder ``OUT/`` beside it (``_blocks_files`` gives the layout).
    block : int, optional
        Block side in lattice cells (voxels, unless anisotropic voxels are subdivided), a
        power of two (default: the largest whose task fits
        `memory`, at most ``mesh_labels``'s root, then the mesh is the in-memory one).
    memory : int, optional
        Bytes each worker may use (also the local workers' limit).
    workers : int
        Local worker processes; 0 runs every task in this process (no Dask).
    scheduler : str, optional
        Address of a running Dask scheduler (instead of a local cluster).
    client : distributed.Client, optional
        A client to use as it is (neither started nor closed here).
    exclude : sequence of int
        Materials not meshed.
    spacing : float or sequence of float, optional
        Voxel size (default: the store's, else 1). Anisotropic voxels are cut into lattice
        cells as :func:`~napari_swa_imesh.mesh.mesh_labels` cuts them (the same mesh).
    material_names : dict of int to str, optional
    subdivide, max_aspect : optional
        As for :func:`~napari_swa_imesh.mesh.mesh_labels`: whether (and to which residual
        aspect) anisotropic voxels are subdivided.
    max_size : float, optional
        Longest element edge (physical units): leaves are split as the in-memory mesher
        splits them (a cap per level, so local to every block).
    refine : int
        Interface refinement ``0 .. 4``, as for
        :func:`~napari_swa_imesh.mesh.mesh_labels`: the lattice is ``2**refine`` times
        finer and cells touching an interface are split to one lattice cell
        (``_refine``; decided per block from its window).
    coarsen : int
        ``0 .. 5``: voxels voted in cubes of ``2**coarsen`` (majority label) first, as
        :func:`~napari_swa_imesh.mesh.mesh_labels` does (``_coarsen``).
    order : {1, 2}
        Element order: 2 adds a node at the midpoint of every edge (10-node tetrahedra,
        6-node triangles; facets of order 2), global ids from the doubled lattice
        (``_quadratic``), as ``write_mesh(..., order=2)`` writes the in-memory mesh.
    periodic : bool
        Opposite faces of the image box carry the same vertices and facets, translated
        (leaves touching the box split to one lattice cell, as ``mesh_labels`` does);
        checked across the box before anything is written (``_periodic``).
    force : bool
        Replace existing outputs.
    retries : int
        Times a failed block is tried again.
    progress : callable, optional
        ``progress(round, done, total)`` after each block (round ``"coarse"`` or ``"mesh"``).

    Returns
    -------
    dict
        Counts (blocks, pieces, points, elements), per-material volumes, worst quality and
        its bound, the block side and whether the mesh equals the in-memory one.

    Raises
    ------
    ValueError
        Bad arguments (before any work), or a check of the assembled mesh failed (then
        nothing is written).
    """
    from ..._atomic import atomic_write, check_writable
    from ..._validation import normalize_spacing
    from ..mesher._door import resolution_arguments, warn_lost_materials
    from ..mesher._imesh import _exclude_array
    from ..mesher._templates import template_quality

    out = Path(output)
    kind = out.suffix.lower()
    if kind not in BLOCK_SUFFIXES:
        raise ValueError(f"block-wise output must end in {' or '.join(BLOCK_SUFFIXES)}; got "
                         f"{out.name!r}.")
    folder = out.with_suffix("")
    check_writable(out, force=force)
    _check_folder(folder, out, force)
    if kind == XDMF_INDEX:
        from ..formats._xdmf import require_h5py

        require_h5py("write")
    if isinstance(order, bool) or order not in (1, 2):
        raise ValueError(f"order must be 1 (linear) or 2 (mid-edge nodes), not {order!r}.")
    if int(workers) < 0:
        raise ValueError(f"workers must be >= 0; got {workers}.")
    source, shape, file_spacing, _ = _open_source(labels)
    d = len(shape)
    sp = normalize_spacing(spacing if spacing is not None else file_spacing, d)
    lattice, max_size, coarsen = resolution_arguments(
        sp, method="template", refine=refine, max_size=max_size, subdivide=subdivide,
        coarsen=coarsen, max_aspect=max_aspect)
    step = tuple(float(h) for h in lattice.step)
    max_level = None
    if max_size is not None:
        # lattice_tree splits a leaf of 2^k cells while 2^k diagonals exceed max_size
        diagonal, max_level = float(np.linalg.norm(lattice.step)), 0
        while not (1 << (max_level + 1)) * diagonal > max_size and max_level < 62:
            max_level += 1
    exclude_arr = _exclude_array(exclude)
    cells = tuple(n * f for n, f in zip(shape, lattice.cells_per_voxel))
    b = choose_block(cells, memory, block, order)
    plan = bk.plan_blocks(shape, b, factors=lattice.cells_per_voxel, max_level=max_level,
                          periodic=periodic, coarsen=coarsen)
    blocks = plan.blocks()

    def src(index):
        if isinstance(source, np.ndarray):
            return source[read_slices(plan, index)[0]]
        return source

    own_client = cluster = None
    runner: _Dask | _Local
    if client is not None:
        runner = _Dask(client)
    elif scheduler or workers > 0:
        own_client, cluster = connect_dask(scheduler, workers=int(workers) or 1,
                                               memory=memory)
        runner = _Dask(own_client)
    else:
        runner = _Local()
    try:
        client_cpu = time.process_time()
        n_workers = (1 if isinstance(runner, _Local) else
                     max(1, len(runner.client.scheduler_info().get("workers", {}))))
        interfaces = tuple(exclude_arr.tolist()) if lattice.refine else None
        coarse = runner.map(timed, [(coarse_task, src(i), plan, i, interfaces)
                                    for i in blocks], retries, progress, "coarse")
        timings = {"coarse": [t for _, t in coarse]}
        coarse = [c for c, _ in coarse]
        counts: dict[int, int] = {}
        before: set[int] = set()
        for _, (values, n, raw) in coarse:
            for v, c in zip(values.tolist(), n.tolist()):
                counts[v] = counts.get(v, 0) + c
            before.update(raw.tolist())
        lost = sorted(before - set(counts))           # voted away by the coarsening
        warn_lost_materials({"level": coarsen, "lost": lost}, material_names)
        present = sorted(m for m in counts if m not in set(exclude_arr.tolist()))
        if not present:
            raise ValueError(f"every voxel is excluded (labels present: {sorted(counts)}, "
                             f"exclude={exclude_arr.tolist()}); nothing is left to mesh.")
        split = bk.balance_grids(plan, {i: c[0] for i, c in zip(blocks, coarse)})
        del coarse
        ids = bf.id_dtype(n_global_ids(plan.shape, order))
        mat = np.dtype(np.int32) if max(present) < 2**31 else np.dtype(np.float64)
        group_ids = bk.group_table(d, present, material_names)
        options = {"exclude": exclude_arr, "present": present, "names": material_names or {},
                   "spacing": step, "kind": kind, "group_ids": group_ids, "ids": ids.str,
                   "mat": mat.str, "order": order}
        with atomic_write([out, folder], force=force, folders=[folder]) as (tmp_out,
                                                                          tmp_folder):
            tmp_folder.mkdir()
            summaries = runner.map(
                timed, [(mesh_task, src(i), plan, i, bk.block_slices(plan, split, i), n,
                         str(tmp_folder), str(out), options)
                        for n, i in enumerate(blocks)], retries, progress, "mesh")
            timings["mesh"] = [t for _, t in summaries]
            summaries = [m for m, _ in summaries]
            report = _check_whole(plan, summaries, counts, present, step,
                                  # every element is a template scaled by the lattice
                                  # step: the worst such template is the proven bound
                                  float(template_quality(d, step)["quality"].max()))
            written = [s for s in summaries if s["n_cells"]]
            if kind == PVTU:
                bf.write_pvtu(tmp_out, folder.name, [bf.piece_names(out, s["number"])[0]
                                                     for s in written], ids, mat)
            else:
                bf.write_xdmf_index(tmp_out, folder.name,
                                    [(bf.piece_names(out, s["number"])[2], s["n_points"],
                                      s["n_cells"]) for s in written], d, ids, mat,
                                    (d + 1) * (d + 2) // 2 if order == 2 else d + 1)
        client_cpu = time.process_time() - client_cpu       # balance, checks, scheduler
    finally:
        if own_client is not None:
            own_client.close()
        if cluster is not None:
            cluster.close()
    report.update({"output": str(out), "pieces_folder": str(folder), "block": plan.block,
                   "blocks": plan.n_blocks, "pieces": len(written),
                   "equals_in_memory": plan.block == 1 << bk.default_top(plan.shape),
                   "spacing": list(sp), "shape": list(shape),
                   "lattice": {"cells_per_voxel": list(lattice.cells_per_voxel),
                               "step": list(step), "refine": lattice.refine},
                   "max_size": max_size, "order": order, "periodic": bool(periodic),
                   "coarsen": {"level": coarsen, "lost": lost},
                   "tasks": {**task_report(timings, n_workers),
                             "client_cpu_s": client_cpu}})
    return report


def _check_folder(folder: Path, out: Path, force: bool) -> None:
    """The pieces' folder may be written: absent, or with `force` a folder holding only
    pieces of `out` (a user's folder of the same name is never replaced)."""
    if not (folder.exists() or folder.is_symlink()):
        return
    if not force:
        raise FileExistsError(f"{folder} already exists (the folder of the pieces of "
                              f"{out.name}); choose another output name, or allow replacing "
                              "it (--force on the command line).")
    stem = out.stem
    foreign = [p.name for p in folder.iterdir() if not folder.is_dir() or not (
        p.name.startswith(f"{stem}_") and p.suffix in (*PARTITIONED.values(), XDMF_INDEX))] \
        if folder.is_dir() else [folder.name]
    if foreign:
        raise FileExistsError(f"{folder} exists and holds files that are not pieces of "
                              f"{out.name} ({foreign[0]}, ...); move it away or choose "
                              "another output name.")


def _check_whole(plan, summaries, counts, present, spacing, bound) -> dict:
    """The checks of the assembled mesh from the pieces' summaries; BlockMeshError with
    what failed, else the report."""
    d = len(plan.shape)
    problems = [f"block {s['index']}: {p}" for s in summaries for p in s["problems"]]
    problems += bk.seam_mismatches(plan, {s["index"]: s["seams"] for s in summaries})
    if plan.periodic:
        problems += _periodic.periodic_mismatches(
            plan, {s["index"]: s["box"] for s in summaries})
    volumes: dict[int, int] = {}
    for s in summaries:
        for m, v in s["volumes"].items():
            volumes[m] = volumes.get(m, 0) + v
    fact = math.factorial(d)
    for m in present:
        if volumes.get(m, 0) != fact * counts[m]:
            problems.append(f"material {m}: mesh volume {volumes.get(m, 0) / fact} voxels, "
                            f"image {counts[m]}")
    worst = max((s["worst"] for s in summaries), default=0.0)
    if worst > bound * (1 + 1e-12):
        problems.append(f"worst radius-to-edge ratio {worst:.6g} above the bound {bound:.6g}")
    if problems:
        raise BlockMeshError(f"the block-wise mesh failed its checks ({len(problems)} "
                             f"problem(s), first: {problems[0]}); nothing was written. This "
                             "is a bug: please report it with the command line.")
    voxel = float(np.prod(spacing))
    groups: dict[str, int] = {}
    for s in summaries:
        for n, c in s["groups"].items():
            groups[n] = groups.get(n, 0) + c
    return {"n_elements": sum(s["n_cells"] for s in summaries),
            "n_points_in_pieces": sum(s["n_points"] for s in summaries),
            "volumes": {int(m): volumes[m] / fact * voxel for m in present},
            "worst_ratio": worst, "quality_bound": bound, "seams_checked": True,
            "groups": groups}
