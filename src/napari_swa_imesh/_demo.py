"""``swa-imesh demo``: the whole pipeline on generated sample data.

Segments a two-texture mosaic (brick and grass from scikit-image's photos: trained on
the top halves of the photos, tested on a mosaic of the held-out bottom halves), prints
its Dice, meshes the labels and writes a ``.vtu``, then simulates steady conduction on the
mesh (grass ten times brick) and prints k_eff per axis. Every input and output goes to
one folder so the run can be replayed step by step with the other sub-commands.
"""

from __future__ import annotations

import time
from pathlib import Path

from ._cli_util import print_json
from ._glossary import glossary_text, terms_in

__all__ = ["add_command", "run_demo"]

DEMO_FILES = ("training.tif", "samples.json", "mosaic.tif", "truth.tif", "res.png",
              "model.npz", "labels.tif", "signatures.csv", "mesh.vtu", "mesh_facets.vtu",
              "field.vtu")
#: the demo's transport: grass conducts ten times better than brick
DEMO_CONDUCTIVITY = {"brick": 1.0, "grass": 10.0}


def add_command(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="segment, mesh and simulate a generated texture mosaic",
        description="Run the whole pipeline on a generated two-texture mosaic: RES, SWA "
                    "segmentation (the recommended method, up to the suggested RES), Dice "
                    "against the truth, "
                    "IMESH triangle mesh written as .vtu, effective conductivity on it "
                    "(grass ten times brick) with the field as field.vtu.")
    p.add_argument("--out", default="swa-imesh-demo", help="folder for every file (created)")
    p.add_argument("--layout", default="halves", choices=["halves", "circle", "voronoi"])
    p.add_argument("--force", action="store_true", help="replace files of an earlier demo")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_demo)


def run_demo(args) -> int:
    from .data import texture_mosaic, texture_training
    from .io import check_writable, write_figure, write_labels
    from .segmentation import evaluate, plot_res_scales, save_samples, segment, write_signatures_csv

    out = Path(args.out)
    # the nearest part of the path that exists must be a folder (a file there made mkdir
    # fail with a bare "[Errno 17] File exists")
    existing = next(p for p in (out, *out.parents) if p.exists())
    if not existing.is_dir():
        raise NotADirectoryError(f"--out {out}: {existing} is a file, not a folder; give a "
                                 "folder for the demo's files (it is created if missing).")
    out.mkdir(parents=True, exist_ok=True)
    for name in DEMO_FILES:                  # refuse before writing anything
        check_writable(out / name, force=args.force)
    seconds: dict[str, float] = {}
    t = time.perf_counter()
    textures = ("brick", "grass")
    train, samples = texture_training(textures)
    mosaic, truth = texture_mosaic(textures, layout=args.layout)
    # the run uses the 8-bit images it leaves behind, so that model.npz applied to
    # mosaic.tif (or refitted on training.tif) gives what the demo printed
    train = (train * 255).round().astype("uint8")
    mosaic = (mosaic * 255).round().astype("uint8")
    write_labels(out / "training.tif", train, force=args.force)
    save_samples(samples, out / "samples.json", force=args.force)
    write_labels(out / "mosaic.tif", mosaic, force=args.force)
    write_labels(out / "truth.tif", truth, force=args.force)
    seconds["data"] = time.perf_counter() - t

    t = time.perf_counter()
    fitted = segment(train, samples)                 # scale: the suggested RES
    result = segment(mosaic, model=fitted.model)
    seconds["segment"] = time.perf_counter() - t
    res = fitted.res                                 # found: segment chose the scale
    if res is None:  # pragma: no cover - segment without a scale always measures RES
        raise RuntimeError("segment() returned no RES statistics without a scale")
    write_figure(plot_res_scales(res, result.scales), out / "res.png", force=args.force,
                 dpi=110)
    fitted.model.save(out / "model.npz", force=args.force)
    write_labels(out / "labels.tif", result.labels, force=args.force)
    write_signatures_csv(result.signatures, out / "signatures.csv", force=args.force)
    ev = evaluate(result.labels, truth)

    summary = {
        "method": result.method, "scales": list(result.scales), "scale": result.scale,
        "suggested_scale": res.suggested_scale,
        "eps_l": fitted.eps_l, "dice": ev["dice"], "mean_dice": ev["mean_dice"],
        "files": str(out),
    }
    try:
        from .mesh import check_mesh, mesh_labels, write_mesh
        have_mesher = True
    except ImportError:  # pragma: no cover - the mesher ships with the package
        have_mesher = False
    if have_mesher:
        t = time.perf_counter()
        mesh = mesh_labels(result.labels, material_names={1: "brick", 2: "grass"})
        checks = check_mesh(mesh, result.labels)
        write_mesh(mesh, out / "mesh.vtu", force=args.force)
        seconds["mesh"] = time.perf_counter() - t
        summary["mesh"] = {"vertices": int(mesh.points.shape[0]), "elements": mesh.n_cells,
                           "worst_ratio": float(mesh.quality.max()),
                           "checks_passed": bool(checks.all_passed)}
        from .simulate import simulate, write_field

        t = time.perf_counter()
        run = simulate(mesh, DEMO_CONDUCTIVITY, labels=result.labels)
        write_field(run, out / "field.vtu", force=args.force)
        seconds["simulate"] = time.perf_counter() - t
        summary["simulate"] = {"k_eff": dict(run.k_eff), "bounds": dict(run.bounds),
                               "choice": run.choice, "dofs": run.dofs,
                               "conductivity": DEMO_CONDUCTIVITY}
    summary["seconds"] = seconds
    if args.json:
        print_json(summary)
        return 0
    lines: list[str] = []
    say = lines.append
    say(f"texture mosaic ({args.layout}) of {', '.join(textures)}: trained on the photos' "
        f"top halves, tested on their bottom halves")
    say(result.describe(notes=False))        # warnings were shown as they came
    say("Dice: " + ", ".join(f"{textures[m - 1]} {d:.3f}" for m, d in ev["dice"].items())
        + f"  (mean {ev['mean_dice']:.3f})")
    if "mesh" in summary:
        m = summary["mesh"]
        say(f"mesh: {m['elements']} triangles, {m['vertices']} vertices, worst "
            f"radius-to-edge {m['worst_ratio']:.3f}, checks "
            f"{'passed' if m['checks_passed'] else 'FAILED'}")
    if "simulate" in summary:
        sim = summary["simulate"]
        say("k_eff (brick 1, grass 10): " + ", ".join(
            f"{a} = {k:.4f} (Reuss {sim['bounds'][a][0]:.3f} .. Voigt {sim['bounds'][a][1]:.3f})"
            for a, k in sim["k_eff"].items()) + f"; {sim['choice']}, {sim['dofs']} unknowns")
    print("\n".join(lines))
    print("terms:\n" + "\n".join(f"  {line}" for line in glossary_text(
        terms_in("\n".join(lines))).splitlines()))
    print(f"files in {out}/: {', '.join(DEMO_FILES)}")
    return 0
