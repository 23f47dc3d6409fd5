"""The ``swa-imesh batch`` command: a cohort segmented, and optionally meshed and simulated.

It chains the three steps, so it lives above them (issue 24): segmentation, mesh and
simulate do not import each other for it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .._cli_util import StepTimer, print_json

__all__ = ["add_command"]


def add_command(subparsers) -> None:
    """Register the ``batch`` sub-command on an argparse sub-parser group."""
    p = subparsers.add_parser(
        "batch", help="segment a cohort of images with one saved model on dask.distributed",
        description="Apply a saved model to many images, one task per image on a Dask "
                    "cluster (a LocalCluster by default). Each labels file is "
                    "OUTDIR/<stem>_labels<suffix> in the input's format, equal to a "
                    "`segment --model` run of that image.")
    p.add_argument("images", nargs="+", help="image files, Zarr stores, folders or globs")
    p.add_argument("--model", required=True, help="a saved model (.npz)")
    p.add_argument("-o", "--output", required=True, help="output folder (must exist)")
    p.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler (default: a LocalCluster)")
    p.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: cores, at most one per image)")
    p.add_argument("--memory", default=None,
                   help="budget of the whole batch (e.g. 8GB), split between the workers")
    p.add_argument("--retries", type=int, default=2, help="tries again per failed image")
    p.add_argument("--mesh", default=None, metavar="SUFFIX",
                   help="also mesh each image's labels into OUTDIR/<stem>_mesh<SUFFIX> "
                        "(.vtu, .msh, .xdmf, .inp, ...)")
    p.add_argument("--simulate", action="store_true",
                   help="also run the steady k_eff simulation of each image's labels, as "
                        "`swa-imesh simulate LABELS -k ...`; k_eff per axis in the table")
    p.add_argument("--conductivity", "-k", nargs="+", action="extend", default=[],
                   metavar="MATERIAL=K",
                   help="with --simulate: conductivity per material, by label or the "
                        "model's names (1=1 2=10 bone=0.1), as in `swa-imesh simulate`")
    p.add_argument("--exclude", type=int, nargs="*", default=[],
                   help="materials the meshes and simulations leave out")
    p.add_argument("--force", action="store_true", help="replace existing labels files")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run_batch)


def _run_batch(args: argparse.Namespace) -> int:
    import os
    import sys

    from .._extras import require

    require("dask", "distributed", "zarr", purpose="the batch command (a Dask cluster)")

    from ..io import check_writable
    from ..segmentation import default_memory, load_model, parse_memory
    from ._batch import (
        connect,
        expand_inputs,
        mesh_for,
        missing_folders,
        output_for,
        quiet_dask,
        run_batch,
    )

    timer = StepTimer()
    images = expand_inputs(args.images)
    model = load_model(args.model)                           # a bad model fails here
    new_folders = missing_folders(args.output)               # made once the checks pass
    if args.mesh:
        from ..mesh import MESH_SUFFIXES

        if args.mesh not in MESH_SUFFIXES:
            raise ValueError(f"--mesh takes a mesh suffix ({', '.join(MESH_SUFFIXES)}); got "
                             f"{args.mesh!r}.")
    if args.exclude and not (args.mesh or args.simulate):
        raise ValueError("--exclude says what the meshes and simulations leave out; add "
                         "--mesh SUFFIX or --simulate.")
    conductivity = _batch_conductivity(args, model)
    for p in images if not new_folders else ():
        check_writable(output_for(p, args.output), force=args.force)
        if args.mesh:
            check_writable(mesh_for(p, args.output, args.mesh), force=args.force)
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be 1 or more; got {args.workers}.")
    if args.retries < 0:
        raise ValueError(f"--retries must be 0 or more; got {args.retries}.")
    budget = parse_memory(args.memory) if args.memory else default_memory()
    workers = args.workers or max(1, min(os.cpu_count() or 1, len(images)))

    def progress(done, total, row):
        bar = "#" * (20 * done // total)
        what = "failed" if "error" in row else f"{row['seconds']:.1f} s"
        print(f"[{bar:<20}] {done}/{total} {Path(row['image']).name}: {what}",
              file=sys.stderr, flush=True)

    for folder in new_folders:
        os.mkdir(folder)
    try:
        with quiet_dask():
            with timer("connect"):
                client = connect(args.scheduler, workers=workers, memory=budget // workers)
            try:
                n = len(client.scheduler_info().get("workers", {})) or workers
                with timer("segment"):
                    rows = run_batch(images, args.model, args.output, client=client,
                                     force=args.force, memory=budget // n,
                                     retries=args.retries, mesh=args.mesh,
                                     exclude=args.exclude, conductivity=conductivity,
                                     progress=None if args.json else progress)
            finally:
                cluster = client.cluster
                client.close()
                if cluster is not None and not args.scheduler:
                    cluster.close()
    finally:
        for folder in reversed(new_folders):     # only if nothing was written there
            try:
                os.rmdir(folder)
            except OSError:
                break
    failed = [r for r in rows if "error" in r]
    if args.json:
        print_json({"images": rows, "workers": n, "scheduler": args.scheduler or "local",
                    "seconds": timer.seconds})
    else:
        print(_batch_table(rows))
        print(f"{len(rows) - len(failed)} of {len(rows)} images segmented on {n} worker(s) "
              f"in {timer.seconds['segment']:.1f} s")
    if failed:
        raise ValueError(f"{len(failed)} of {len(rows)} images failed ("
                         f"{Path(failed[0]['image']).name}: {failed[0]['error']}); fix them "
                         "and run the batch again for those.")
    return 0


def _batch_conductivity(args: argparse.Namespace, model) -> dict | None:
    """``--conductivity`` by label, checked against the model's materials (every one not
    excluded needs a value) before any work; None without ``--simulate``."""
    if bool(args.simulate) != bool(args.conductivity):
        raise ValueError("--simulate needs --conductivity MATERIAL=K for each material (and "
                         "--conductivity goes with --simulate); give both or neither.")
    if not args.simulate:
        return None
    from ..simulate import conductivity_tensors, material_label, parse_conductivity_args

    parsed = parse_conductivity_args(args.conductivity)
    names = {m.label: m.name for m in model.materials}
    kept = [m for m in model.labels if m not in set(args.exclude)]
    conductivity_tensors(parsed, kept, model.ndim, names)       # one sentence if wrong
    return {material_label(k, names): v for k, v in parsed.items()}


def _batch_table(rows: list[dict]) -> str:
    """Per image: labels file, seconds, every material's volume, and k_eff per axis."""
    labels = sorted({int(k) for r in rows for k in r.get("volumes", {})})
    axes = list(dict.fromkeys(a for r in rows for a in r.get("simulate", {}).get("k_eff", {})))
    head = (["image", "labels", "seconds"] + [f"volume {k}" for k in labels]
            + [f"k_eff {a}" for a in axes])
    body = [[Path(r["image"]).name, Path(r["output"]).name,
             "failed" if "error" in r else f"{r['seconds']:.2f}"]
            + [f"{r['volumes'][k]['volume']:.6g}" if "volumes" in r else ""
               for k in labels]
            + [f"{r['simulate']['k_eff'][a]:.6g}" if "simulate" in r else "" for a in axes]
            for r in rows]
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body)]
    return "\n".join("  ".join(str(x).ljust(w) for x, w in zip(line, widths))
                     for line in [head, *body])
