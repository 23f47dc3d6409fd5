"""Sub-commands of ``swa-imesh`` for segmentation: res, segment, samples-from-truth, evaluate."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .._cli_util import StepTimer, print_json
from .._glossary import define
from .._steps import run_steps
from ..io import check_writable

# re-exported for the classify widget until it imports them from the library
from ._signatures import signatures_csv_text

__all__ = ["add_commands"]


def add_commands(subparsers) -> None:
    """Register the segmentation sub-commands on an argparse sub-parser group."""
    p = subparsers.add_parser(
        "res", help="tile-moment statistics against scale and the suggested RES",
        description="Print (and plot) the statistics of tile moments per material against "
                    "scale, and the suggested representative elementary scale, capped at "
                    "the largest scale the --method classifier trains at on these boxes. "
                    f"RES: {define('RES')}")
    p.add_argument("image")
    p.add_argument("--samples", required=True, help="samples JSON (see README)")
    p.add_argument("--max-scale", type=int, default=None)
    p.add_argument("--method", default="recommended", choices=["recommended", "reference"],
                   help="the segment method the suggestion must train (default recommended: "
                        "windows of 2^j + 1 px inside a box of every material; reference: "
                        "enough full tiles of 2^j px)")
    p.add_argument("--plot", default=None, help="write the Figure 2.14-style plot (PNG/PDF/SVG)")
    p.add_argument("--gray", action="store_true", help="convert an RGB picture to grey")
    p.add_argument("--force", action="store_true", help="replace an existing plot file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run_res)

    p = subparsers.add_parser(
        "segment", help="classify the image into a full-resolution label image",
        description=f"SWA: {define('SWA')} "
                    "Segment an image with SWA, fitted on sample boxes (or a saved model). "
                    "Default: the recommended method (multi-scale per-pixel statistics, "
                    "coarse-to-fine at boundaries, MRF, bias correction); --method reference "
                    "for the reference's tiles at one scale, feature set and classifier.")
    p.add_argument("image")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--samples", help="samples JSON to fit a classifier on")
    src.add_argument("--model", help="a saved model (.npz) to apply")
    p.add_argument("--method", default="recommended", choices=["recommended", "reference"],
                   help="default: recommended (a saved model brings its own)")
    p.add_argument("--scale", type=int, default=None,
                   help="recommended: the largest scale considered (windows of 2^j + 1 px); "
                        "reference: the tile scale j (tiles of 2^j px); default: the "
                        "suggested RES")
    p.add_argument("--features", default=None,
                   help="reference method only: feature set F1..F7 (default F1)")
    p.add_argument("--classifier", default=None, choices=["gm", "md", "lvq"],
                   help="reference method only: classifier (default gm)")
    p.add_argument("--sieve", type=int, default=0,
                   help="remove components smaller than N tiles (reference) or pixels "
                        "(recommended)")
    p.add_argument("--model-out", default=None, help="save the fitted model (.npz)")
    p.add_argument("--signatures", default=None, help="write the material signatures (CSV)")
    p.add_argument("--res-plot", default=None,
                   help="write the RES plot with the scales used shaded (PNG/PDF/SVG; needs "
                        "--samples)")
    p.add_argument("--tiles", action="store_true",
                   help="write one label per tile instead of full resolution")
    p.add_argument("--truth", default=None, help="ground truth to report Dice against")
    p.add_argument("--gray", action="store_true", help="convert an RGB picture to grey")
    p.add_argument("-o", "--output", required=True,
                   help="labels file: .npy, .tif, .nii.gz or .png; or a .zarr store, "
                        "written chunk by chunk")
    p.add_argument("--memory", default=None,
                   help="work chunk by chunk within this budget for the whole process (e.g. "
                        "2GB; default half the memory available); with --samples the fit "
                        "reads only the boxes; Zarr images and outputs are always chunked")
    p.add_argument("--workers", type=int, default=None,
                   help="threads of the chunked path (default: planned from the budget)")
    p.add_argument("--force", action="store_true", help="replace existing output files")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run_segment)

    p = subparsers.add_parser(
        "samples-from-truth", help="sample boxes from the largest homogeneous blocks of a truth",
        description="Write a samples JSON whose boxes are the largest homogeneous blocks of "
                    "each material in a ground-truth label image (its 2^d-tree).")
    p.add_argument("truth")
    p.add_argument("--scale", type=int, default=None,
                   help="prefer blocks holding at least 2^d tiles at this scale")
    p.add_argument("--per-material", type=int, default=4)
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--force", action="store_true")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run_samples_from_truth)

    p = subparsers.add_parser(
        "evaluate", help="Dice, Jaccard and confusion matrix against a truth")
    p.add_argument("labels")
    p.add_argument("--truth", required=True)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run_evaluate)


def _run_res(args: argparse.Namespace) -> int:
    from .._zarr_io import is_lazy, open_lazy
    from ..io import check_figure_path, read_image, write_figure
    from ._res import format_res_table, plot_res, res_statistics, res_statistics_of_boxes
    from ._samples import load_samples

    timer = StepTimer()
    if args.plot:
        check_figure_path(args.plot, force=args.force)
    if args.max_scale is not None and args.max_scale < 0:
        raise ValueError(f"--max-scale must be 0 or more; got {args.max_scale}.")
    lazy = not args.gray and is_lazy(args.image)
    with timer("read"):
        if lazy:   # a store or .npy stays on disk: the statistics read the boxes only
            image, _ = open_lazy(args.image)
        else:
            image, _ = read_image(args.image, gray=args.gray)
        samples = load_samples(args.samples)
    with timer("res"):
        stats = (res_statistics_of_boxes(image, samples, max_scale=args.max_scale,
                                         method=args.method) if lazy
                 else res_statistics(image, samples, max_scale=args.max_scale,
                                     method=args.method))
    if args.plot:
        with timer("plot"):
            write_figure(plot_res(stats), args.plot, force=args.force)
    if args.json:
        print_json({**stats.to_dict(), "plot": args.plot, "seconds": timer.seconds})
    else:
        print(format_res_table(stats))
        if args.plot:
            print(f"plot written to {args.plot}")
    return 0


def _check_segment_args(args: argparse.Namespace) -> None:
    """Every argument and output path, before any work (nothing is written on failure)."""
    from ..io import LABEL_SUFFIXES, check_figure_path, image_suffix
    from ._model_io import check_model_path

    if image_suffix(args.output) not in LABEL_SUFFIXES:
        raise ValueError(f"cannot write labels as {Path(args.output).name!r}; -o takes "
                         f"{', '.join(LABEL_SUFFIXES)}.")
    outputs = [args.output]
    if args.model_out:
        check_model_path(args.model_out)
        outputs.append(args.model_out)
    if args.signatures:
        outputs.append(args.signatures)
    if args.res_plot:
        if not args.samples:
            raise ValueError("--res-plot needs --samples: the RES statistics come from the "
                             "sample boxes.")
        check_figure_path(args.res_plot, force=args.force)
        outputs.append(args.res_plot)
    for p in outputs:
        check_writable(p, force=args.force)
    if len({Path(p).resolve() for p in outputs}) != len(outputs):
        raise ValueError("two outputs name the same file; give -o, --model-out, "
                         "--signatures and --res-plot different names.")
    if args.sieve < 0:
        raise ValueError(f"--sieve must be 0 or more; got {args.sieve}.")
    if args.scale is not None and args.scale < 0:
        raise ValueError(f"--scale must be 0 or more; got {args.scale}.")
    given = [f for f, v in (("--features", args.features), ("--classifier", args.classifier))
             if v is not None]
    if given and (args.model or args.method != "reference"):
        raise ValueError(
            f"{' and '.join(given)} belong to the reference method; "
            + ("a saved model brings its own, drop them." if args.model else
               "add --method reference or drop them."))


def _run_segment(args: argparse.Namespace) -> int:
    from ..io import (
        atomic_write,
        check_label_format,
        grid_affine,
        is_nifti,
        label_array,
        read_affine,
        read_image,
        write_labels_to,
    )
    from ._metrics import evaluate
    from ._model_io import load_model, write_model_to
    from ._res import plot_res_scales, res_statistics
    from ._samples import load_samples
    from ._segment import segment_steps
    from ._tiles import tile_placement

    timer = StepTimer()
    if _chunked_run(args):
        return 0
    _check_segment_args(args)
    with timer("read"):
        image, spacing = read_image(args.image, gray=args.gray)
        # a NIfTI image's placement goes to NIfTI labels (the mesh of them lies on it)
        affine = read_affine(args.image) if is_nifti(args.output) else None
        samples = load_samples(args.samples) if args.samples else None
        model = load_model(args.model) if args.model else None
        truth = read_image(args.truth)[0] if args.truth else None
    if truth is not None and truth.shape != image.shape:
        raise ValueError(f"--truth has shape {truth.shape} but the image has {image.shape}; "
                         "give the truth of this image.")
    materials = samples.labels if samples is not None else model.labels
    # the format must hold labels of the image's shape up to the largest material (a
    # broadcast view: no memory, and a refusal names the real shape)
    check_label_format(args.output, np.broadcast_to(
        label_array([max(materials)]).reshape((1,) * image.ndim), image.shape))
    gen = segment_steps(image, samples, scale=args.scale, feature_set=args.features,
                        classifier=args.classifier, sieve=args.sieve, model=model,
                        spacing=spacing, method=args.method)
    with timer("segment"):
        result = run_steps(gen)
    with timer("write"):
        if args.tiles:
            # the header describes the tile grid: 2^j voxels per tile, first tile's centre
            tile_spacing, origin = tile_placement(result.scale, spacing, image.ndim)
            labels, out_spacing = label_array(result.tile_labels), tile_spacing
            if affine is not None:
                affine = grid_affine(affine, 1 << result.scale, image.ndim)
        else:
            labels, out_spacing, origin = label_array(result.labels), spacing, None
        check_label_format(args.output, labels)
        figure = None
        if args.res_plot:
            # a reference run at a given --scale computes no RES; the others reuse theirs
            stats = result.res if result.res is not None else res_statistics(image, samples)
            figure = plot_res_scales(stats, result.scales or (result.scale,))
        outputs = [p for p in (args.output, args.model_out, args.signatures, args.res_plot)
                   if p]
        with atomic_write(outputs, force=args.force) as temps:
            temps = dict(zip(outputs, temps))
            write_labels_to(temps[args.output], labels, spacing=out_spacing, origin=origin,
                            affine=affine)
            if args.model_out:
                write_model_to(temps[args.model_out], *result.model.file_content())
            if args.signatures:
                temps[args.signatures].write_text(signatures_csv_text(result.signatures))
            if figure is not None:
                figure.savefig(temps[args.res_plot], dpi=120)
    summary = result.summary()
    summary["seconds"] = {**summary["seconds"], **timer.seconds}
    summary["output"] = args.output
    if truth is not None:
        ev = evaluate(result.labels, truth)
        summary["dice"] = ev["dice"]
        summary["mean_dice"] = ev["mean_dice"]
    if args.json:
        print_json(summary)
    else:
        print(result.describe(notes=False))          # the warnings went to stderr
        if truth is not None:
            print("  Dice: " + ", ".join(f"{k}: {v:.3f}" for k, v in summary["dice"].items())
                  + f"  (mean {summary['mean_dice']:.3f})")
        print(f"labels written to {args.output}")
    return 0


def _chunked_run(args: argparse.Namespace) -> bool:
    """``segment`` chunk by chunk when :func:`~._apply.wants_chunks` says so (``--model``:
    applied; ``--samples``: fitted on the boxes read from the store, then applied); False
    to run in memory."""
    from ._apply import apply_model, fit_apply, wants_chunks
    from ._chunked import parse_memory
    from ._model_io import load_model
    from ._samples import load_samples

    memory = parse_memory(args.memory) if args.memory is not None else None
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be 1 or more; got {args.workers}.")
    model = load_model(args.model) if args.model else None
    if not wants_chunks(args.image, args.output, model, memory=memory):
        return False
    whole = [f for f, v in (("--sieve", args.sieve), ("--tiles", args.tiles),
                            ("--signatures", args.signatures), ("--truth", args.truth),
                            ("--model-out", args.model_out and model is not None),
                            ("--res-plot", args.res_plot),
                            ("--scale", args.scale is not None and model is not None),
                            ("--gray", args.gray)) if v]
    if whole:
        raise ValueError(f"{', '.join(whole)} need(s) the whole image in memory; drop "
                         f"{'them' if len(whole) > 1 else 'it'} to segment chunk by chunk "
                         "(a Zarr image or output, or --memory).")
    if model is None and args.method != "recommended":
        raise ValueError("the reference method fits in memory; segment this image with the "
                         "recommended method (drop --method) or fit on a crop that fits in "
                         "memory with --model-out, then apply the model with --model.")
    if model is None:
        summary = fit_apply(args.image, load_samples(args.samples), args.output,
                            max_scale=args.scale, memory=memory, workers=args.workers,
                            force=args.force, model_out=args.model_out)
    else:
        summary = apply_model(args.image, model, args.output, memory=memory,
                              workers=args.workers, force=args.force, chunked=True)
    if args.json:
        print_json(summary)
    else:
        plan = summary["plan"]
        if "fit" in summary:
            fit = summary["fit"]
            print(f"fitted on the sample boxes read from the store in {fit['seconds']:.1f} s:"
                  f" scales {fit['coarse_scale']}..{fit['finest_scale']}, bias correction "
                  f"{'on' if fit['bias_correction'] else 'off'}")
        print(f"labels written to {args.output} chunk by chunk: chunks of "
              f"{'x'.join(map(str, plan['chunks']))} voxels with a margin of {plan['halo']} "
              f"px, {plan['workers']} thread(s), budget {plan['memory'] / 1e9:.2f} GB, "
              f"{summary['seconds']:.1f} s")
        for label, v in summary["volumes"].items():
            print(f"  material {label}: {v['voxels']} voxels, volume {v['volume']:.6g}")
    return True


def _run_samples_from_truth(args: argparse.Namespace) -> int:
    from ..io import read_image
    from ._samples import samples_from_truth, save_samples

    check_writable(args.output, force=args.force)
    truth, _ = read_image(args.truth)
    samples = samples_from_truth(truth, scale=args.scale, per_material=args.per_material)
    save_samples(samples, args.output, force=args.force)
    if args.json:
        print_json({**samples.to_dict(), "output": args.output})
    else:
        print(f"{len(samples.boxes)} boxes for {len(samples.materials)} materials written "
              f"to {args.output}")
    return 0


def _run_evaluate(args: argparse.Namespace) -> int:
    from ..io import read_image
    from ._metrics import evaluate

    labels, _ = read_image(args.labels)
    truth, _ = read_image(args.truth)
    ev = evaluate(labels, truth)
    if args.json:
        print_json(ev)
    else:
        for m in ev["materials"]:
            print(f"material {m}: Dice {ev['dice'][m]:.4f}  Jaccard {ev['jaccard'][m]:.4f}")
        print(f"mean Dice {ev['mean_dice']:.4f}, pixel accuracy {ev['accuracy']:.4f}")
    return 0
