"""Sub-commands of ``swa-imesh`` for meshing: mesh, bounds.

``swa-imesh mesh LABELS -o MESH`` meshes a label image and writes the format the suffix
names; ``swa-imesh bounds --dim d`` prints the quality of the template simplices.
Exit status: 0 on success, 2 for bad input (one line on stderr, from ``cli.main``), 1
when the mesh was written but one of its checks failed (a bug to report, not bad input).
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .._cli_util import StepTimer, parse_material_names, print_json
from .._validation import OptionError, normalize_spacing
from .checks._checks import check_mesh
from .formats._export import MESH_SUFFIXES
from .formats._registry import mesh_format, mesh_formats
from .mesher._subdivision import check_max_aspect
from .model._memory import (
    available_memory,
    count_boundary_voxels,
    current_rss,
    estimate_mesh_memory,
    format_bytes,
    parse_memory_size,
)

__all__ = ["add_commands", "parse_material_names"]


def add_commands(subparsers) -> None:
    """Register the meshing sub-commands on an argparse sub-parser group."""
    p = subparsers.add_parser(
        "mesh", help="mesh a label image into triangles (2-D) or tetrahedra (3-D)",
        description="Mesh a 2-D or 3-D label image on a balanced 2^d-tree (IMESH); every "
                    "element carries one material. The output suffix picks the format: "
                    f"{', '.join(MESH_SUFFIXES)} (.node/.ele write both files: Triangle in "
                    "2-D, TetGen in 3-D; .xdmf writes its .h5 beside it).")
    p.add_argument("labels", metavar="LABELS",
                   help="label image (.tif, .npy, .nii/.nii.gz, .png); 0 is background")
    p.add_argument("-o", "--output", required=True, metavar="MESH",
                   help="mesh file to write; an existing file is only replaced with --force")
    p.add_argument("--method", choices=("template", "delaunay"), default="template",
                   help="template (look-up tables, conforming; default) or delaunay "
                        "(the reference's Qhull step, for comparison)")
    p.add_argument("--exclude", type=int, nargs="+", action="extend", default=[], metavar="L",
                   help="labels not to mesh, e.g. --exclude 0 for the background")
    p.add_argument("--spacing", type=float, nargs="+", default=None, metavar="S",
                   help="voxel size per axis in array order (one value = isotropic); "
                        "default: from the file, else 1")
    p.add_argument("--index-space", action="store_true",
                   help="NIfTI only: write the mesh in the image's own frame (x, y, z = "
                        "column, row, plane times the header zooms, voxel corner 0 at 0) "
                        "instead of the world frame of the file's affine (the default)")
    p.add_argument("--material-names", nargs="+", action="extend", default=[],
                   metavar="ID=NAME", help="names for materials, e.g. 1=bone 2=soft "
                                           "(Gmsh physical groups, Abaqus element sets)")
    p.add_argument("--abaqus-elements", choices=("mechanical", "heat"), default="mechanical",
                   help="element types of an .inp: mechanical (CPS3/C3D4, order 2 "
                        "CPS6/C3D10; default) or heat (DC2D3/DC3D4, order 2 DC2D6/DC3D10; "
                        "for *HEAT TRANSFER)")
    p.add_argument("--order", default="1", metavar="1|2",
                   help="element order: 1 (default) or 2 (a node at the midpoint of every "
                        "edge: 6-node triangles, 10-node tetrahedra; facets of order 2)")
    p.add_argument("--facet-groups", default="all", metavar="all|none|NAME,NAME",
                   help="facet groups to write (box sides xmin..zmax, interface_<A>_<B>, "
                        "exterior_<A>; * patterns allowed, e.g. xmin,xmax,interface_*): "
                        "all (default) or none; .vtu gets them in <stem>_facets.vtu, .xdmf "
                        "in <stem>_xdmf_facets.vtu, "
                        ".node/.ele in .poly (2-D) / .face (3-D), .msh as physical groups, "
                        ".inp as *NSET/*SURFACE")
    p.add_argument("--msh-ascii", action="store_true",
                   help="write .msh as Gmsh 4.1 ASCII instead of binary")
    p.add_argument("--refine", type=int, default=0, metavar="K",
                   help="elements at material interfaces are at most 2^-K voxels per axis "
                        "(0..4, default 0; anisotropy cells count); bounds unchanged")
    p.add_argument("--max-size", type=float, default=None, metavar="H",
                   help="longest element edge allowed, in physical units (larger leaves "
                        "are split); at least the diagonal of one lattice cell")
    p.add_argument("--coarsen", type=int, default=0, metavar="K",
                   help="mesh the labels in blocks of 2^K voxels, each taking its majority "
                        "label (0..5; default 0, exact): fewer elements for large smooth "
                        "volumes; the per-material volume change is printed")
    p.add_argument("--periodic", action="store_true",
                   help="the same vertices and facets on opposite faces of the box "
                        "(translated), for periodic boundary conditions")
    p.add_argument("--no-subdivide", action="store_true",
                   help="mesh anisotropic voxels as stretched templates (no physical "
                        "quality bound) instead of subdividing them into nearly cubic cells")
    p.add_argument("--max-aspect", type=float, default=None, metavar="A",
                   help="cut voxels into the fewest cells of aspect <= A (default 1.25: "
                        "ratio <= 1.3754, dihedral >= 29.5 deg); larger A, fewer elements, "
                        "looser bound (see: swa-imesh bounds --dim 3 --spacing ...)")
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    p.add_argument("--no-check", action="store_true", help="skip the conformity checks")
    p.add_argument("--full-check", action="store_true",
                   help="check by sorting every element facet, as for a mesh made elsewhere "
                        "(same verdict as the default one-pass check; slower)")
    p.add_argument("--memory-limit", default="auto", metavar="BYTES|auto|off",
                   help="refuse to start when the run's estimated peak memory exceeds "
                        "this: auto (default: available now, cgroup, ulimit -v), a size "
                        "such as 8G, or off; --json reports it as memory_estimate_bytes")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_run_mesh)

    p = subparsers.add_parser(
        "bounds", help="print the quality of the template simplices",
        description="Print the distinct template simplices of a dimension with their "
                    "radius-to-edge ratio and angles: the quality the mesher guarantees.")
    p.add_argument("--dim", type=int, required=True, metavar="D", help="dimension (2 or 3)")
    p.add_argument("--spacing", type=float, nargs="+", default=None, metavar="S",
                   help="voxel spacing: also print what each --max-aspect gives for it "
                        "(cells per voxel, bound, elements) and the lattice used")
    p.add_argument("--max-aspect", type=float, default=None, metavar="A",
                   help="with --spacing: the limit to mark (default 1.25, the mesher's)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_run_bounds)


def _run_mesh(args: argparse.Namespace) -> int:
    from ..io import image_suffix, read_image
    from .formats._export import mesh_output_paths, write_mesh
    from .mesher._imesh import plan_mesh

    timer = StepTimer()
    # fail before the (possibly long) meshing on a bad option, suffix or existing file
    peek = _peek_shape_dtype(args.labels)
    write_options = _write_options(args, None if peek is None else len(peek[0]))
    mesh_output_paths(args.output, force=args.force,
                      facet_groups=write_options["facet_groups"])
    names = parse_material_names(args.material_names)
    limit = parse_memory_size(args.memory_limit)
    if args.spacing:
        normalize_spacing(args.spacing, len(args.spacing))  # a bad value fails before reading
    _check_resolution_args(args)
    # from the file's header: refuse a volume whose labels and grids alone cannot fit
    placement = _placement(args, peek)
    if peek is not None and len(peek[0]) in (2, 3) and limit != 0:
        _check_memory(args, estimate_mesh_memory(peek[0], peek[1], n_boundary=0,
                                                 max_label=0, check=not args.no_check),
                      limit, peek[0], peek[1], at_least=True)
    with timer("read"):
        image, file_spacing = read_image(args.labels)
    if image_suffix(args.labels) in (".png", ".jpg", ".jpeg") and image.ndim == 3:
        raise ValueError(
            f"{Path(args.labels).name} is a colour picture (shape {image.shape}); a label "
            "image has one value per pixel. Save the labels as a grey PNG, .tif or .npy."
        )
    # the library's door: labels keep their dtype (no copy), every option checked once;
    # the plan is what the library's mesh_labels and the Mesh tab run too
    plan = plan_mesh(
        image, method=args.method, exclude=tuple(args.exclude),
        spacing=placement[0] if placement else args.spacing if args.spacing else file_spacing,
        material_names=names, refine=args.refine, max_size=args.max_size,
        subdivide=not args.no_subdivide, coarsen=args.coarsen, periodic=args.periodic,
        max_aspect=args.max_aspect, name=f"labels in {Path(args.labels).name}")
    del image
    labels, exclude = plan.labels, plan.exclude
    fmt = mesh_format(args.output)
    if fmt.check_labels is not None:        # a limit of the format on the label values
        fmt.check_labels(labels, exclude)
    # the dimension is known now: the box sides it has, and .poly or .face
    write_options = _write_options(args, labels.ndim)
    mesh_output_paths(args.output, force=args.force,
                      facet_groups=write_options["facet_groups"], ndim=labels.ndim)
    with timer("estimate"):
        estimate = estimate_mesh_memory(labels.shape, labels.dtype,
                                        n_boundary=count_boundary_voxels(labels),
                                        max_label=int(labels.max()), check=not args.no_check,
                                        cells_per_voxel=plan.lattice.cells_per_voxel)
    if limit != 0:
        _check_memory(args, estimate, limit, labels.shape, labels.dtype)

    del labels
    with timer("mesh"):
        # the checks below run beside the writer, not in the plan (report_checks)
        mesh, tree, labels = plan.run(report_checks=False)
    del plan
    mesh.world = placement[1] if placement else None
    with ThreadPoolExecutor(1) as pool:
        # both only read the mesh; numpy's gathers and sorts release the GIL
        if not args.no_check:
            timer.seconds["check"] = 0.0
            checked = pool.submit(_timed_check, timer, mesh, labels, exclude, tree,
                                  args.full_check)
        del tree, labels  # the writers need only the mesh
        with timer("write"):
            written = write_mesh(mesh, args.output, force=args.force, **write_options)
        checks = {"skipped": True} if args.no_check else checked.result()

    report = _mesh_report(args, mesh, checks, written, timer.seconds)
    report["memory_estimate_bytes"] = estimate
    report["frame"] = "world" if placement else "image"
    report["world"] = placement[1].tolist() if placement else None
    if args.json:
        print_json(report)
    else:
        print(_mesh_text(report))
    if not args.no_check and not checks.get("all_passed", False):
        failed = ", ".join(k for k, v in checks.items() if v is False and k != "all_passed")
        advice = ("the delaunay method is kept for comparison and is known to fail them; "
                  "use --method template for a mesh to compute on"
                  if args.method == "delaunay" else "please report this with the input")
        print(f"swa-imesh mesh: warning: the mesh was written but failed the checks "
              f"({failed}); {advice}.", file=sys.stderr)
        return 1
    return 0


def _timed_check(timer, mesh, labels, exclude, tree, full) -> dict:
    with timer("check"):
        return check_mesh(mesh, labels, exclude=exclude, tree=tree, full=full).to_dict()


def _check_resolution_args(args) -> None:
    """Refine and coarsen levels in range before any reading (the size cap needs the
    spacing, so it is checked with it)."""
    from .mesher._coarsen import check_coarsen
    from .mesher._imesh import check_periodic
    from .mesher._lattice import check_refine

    check_refine(args.refine)
    if args.max_aspect is not None:
        check_max_aspect(args.max_aspect, "--max-aspect", subdivide=not args.no_subdivide)
    check_coarsen(args.coarsen)
    check_periodic(args.method, args.periodic)
    if args.max_size is not None and not (np.isfinite(args.max_size) and args.max_size > 0):
        raise ValueError(f"--max-size must be a positive length; got {args.max_size}.")


def _placement(args, peek) -> tuple | None:
    """(spacing, world) from a NIfTI file's affine (its header only, before any work), or
    None: the image's own frame (other formats, ``--index-space``)."""
    from ..io import is_nifti, read_affine
    from .model._world import image_placement

    name = Path(args.labels).name
    if not is_nifti(args.labels):
        if args.index_space:
            raise ValueError(f"--index-space applies to NIfTI files (.nii, .nii.gz), whose "
                             f"affine places the mesh; {name} has none and is always meshed "
                             "in its own frame, so drop the option.")
        return None
    if args.index_space:
        return None
    if args.spacing:
        raise ValueError(f"--spacing conflicts with the affine of {name}, which sets the voxel "
                         "sizes and places the mesh in world coordinates; drop --spacing, or "
                         "add --index-space to mesh in the image's own frame with it.")
    read_affine(args.labels)          # a bad header is refused before the pixels
    if peek is None or len(peek[0]) not in (2, 3):
        return None                   # the reader or the mesher's door says what is wrong
    return image_placement(args.labels, len(peek[0]))


def _write_options(args, ndim: int | None) -> dict:
    """The keyword arguments of ``write_mesh`` from the flags, checked (ValueError in the
    flags' words) before any meshing."""
    from .formats._export import check_write_options

    if args.order not in ("1", "2"):
        raise ValueError(f"--order must be 1 or 2, not {args.order!r}.")
    if args.msh_ascii and "binary" not in mesh_format(args.output).options:
        ascii_ = " or ".join(f.suffix for f in mesh_formats() if "binary" in f.options)
        raise ValueError(f"--msh-ascii applies to {ascii_} output only, not "
                         f"{Path(args.output).name}; leave it out or write {ascii_}.")
    text = args.facet_groups.strip()
    groups = text if text in ("all", "none") else [n.strip() for n in text.split(",")]
    if isinstance(groups, list) and not all(groups):
        raise ValueError(f"--facet-groups expects all, none or names separated by commas "
                         f"(e.g. xmin,xmax,interface_*); got {args.facet_groups!r}.")
    options = {"order": int(args.order), "binary": not args.msh_ascii,
               "facet_groups": groups, "abaqus_elements": args.abaqus_elements}
    try:
        options["facet_groups"] = check_write_options(args.output, ndim=ndim, **options)
    except OptionError as exc:            # the library's keyword, named as the flag
        flag = "--" + exc.option.replace("_", "-")
        raise exc.as_option(flag, drop=f"drop {flag}") from None
    return options


def _check_memory(args, estimate: int, limit: int | None, shape, dtype, *,
                  at_least: bool = False) -> None:
    """Refuse (ValueError, exit 2) when the estimated peak does not fit the limit.

    With ``limit=None`` (auto) the part not yet resident must fit the available memory.
    """
    if limit is None:
        free = available_memory()
        if free is None:
            return
        room = free + current_rss()
        source = "available"
    else:
        room, source = limit, "allowed by --memory-limit"
    if estimate <= room:
        return
    size = "x".join(str(n) for n in shape)
    raise ValueError(
        f"meshing {Path(args.labels).name} ({size} {np.dtype(dtype).name}) needs "
        f"{'at least ' if at_least else ''}about {format_bytes(estimate)} of memory by the "
        f"estimate, but {format_bytes(room)} is {source}; crop the volume, coarsen "
        "(downsample) the labels, or mesh a sub-volume"
        f"{'' if args.exclude else ' (add --exclude 0 if background dominates)'}"
        f"{'' if args.no_check else ', or skip the checks with --no-check'}; "
        "--memory-limit overrides the estimate."
    )


def _peek_shape_dtype(path):
    """(shape, dtype) from a .npy, .tif or NIfTI header without reading the pixels, or None."""
    from ..io import image_suffix

    suffix = image_suffix(path)
    try:
        if suffix == ".npy":
            arr = np.load(path, mmap_mode="r", allow_pickle=False)
            return tuple(arr.shape), arr.dtype
        if suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                series = tif.series[0]
                return tuple(series.shape), np.dtype(series.dtype)
        if suffix in (".nii", ".nii.gz"):
            from .._headers import load_nifti

            img = load_nifti(Path(path))
            return tuple(img.shape), np.dtype(img.get_data_dtype())
    except Exception:  # the reader proper reports unreadable files
        return None
    return None


def _mesh_report(args, mesh, checks, written, seconds) -> dict:
    """The ``--json`` object: counts, quality, checks and seconds per step."""
    info, recipe = mesh.info, mesh.recipe
    materials, counts = _material_counts(mesh.material)
    report = {
        "command": "mesh",
        "input": str(args.labels),
        "output": [str(p) for p in written],
        "method": args.method,
        "order": int(args.order),
        "dim": mesh.ndim,
        "shape": list(mesh.shape),
        "spacing": list(mesh.spacing),
        "exclude": list(recipe.exclude),
        "leaves_before_balance": info.get("n_leaves_tree"),
        "leaves_after_balance": info.get("n_leaves_balanced"),
        "leaves_meshed": info.get("n_leaves_meshed"),
        "vertices": int(len(mesh.points)),
        "elements": mesh.n_cells,
        "elements_per_material": {int(m): int(c) for m, c in zip(materials, counts)},
        "material_names": {int(m): mesh.material_names.get(int(m), f"material_{int(m)}")
                           for m in materials},
        "worst_ratio": float(np.nanmax(mesh.quality)),
    }
    cd = mesh.cell_data
    if mesh.ndim == 2 and "min_angle" in cd:
        report["min_angle"] = float(np.nanmin(cd["min_angle"]))
        if "max_angle" in cd:
            report["max_angle"] = float(np.nanmax(cd["max_angle"]))
        elif "angle_range" in info:
            report["max_angle"] = float(info["angle_range"][1])
    if mesh.ndim == 3 and "min_dihedral" in cd:
        report["min_dihedral"] = float(np.nanmin(cd["min_dihedral"]))
        report["max_dihedral"] = float(np.nanmax(cd["max_dihedral"]))
    report["lattice"] = None if recipe.lattice is None else recipe.lattice.describe()
    if "coarsen" in info:
        report["coarsen"] = info["coarsen"]
    if recipe.max_size is not None:
        report["max_size"] = recipe.max_size
    report["checks"] = checks
    report["seconds"] = {
        "read": seconds.get("read", 0.0),
        "mesh": seconds.get("mesh", 0.0),
        "mesh_steps": dict(info.get("seconds", {})),
        "check": seconds.get("check", 0.0),
        "write": seconds.get("write", 0.0),
        "estimate": seconds.get("estimate", 0.0),
    }
    return report


def _material_counts(material: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Materials present and their element counts: a bincount for label-sized ids (a
    sort of tens of millions of elements took seconds)."""
    top = int(material.max()) if material.size else 0
    if material.size and material.min() >= 0 and top < max(1 << 20, material.size):
        counts = np.bincount(material, minlength=top + 1)
        present = np.flatnonzero(counts)
        return present, counts[present]
    return np.unique(material, return_counts=True)


def _mesh_text(r: dict) -> str:
    kind = "triangles" if r["dim"] == 2 else "tetrahedra"
    shape = "x".join(str(s) for s in r["shape"])
    spacing = " x ".join(f"{s:g}" for s in r["spacing"])
    lines = [
        f"meshed {r['input']} ({shape}, spacing {spacing}) with {r['method']}: "
        f"{r['vertices']} vertices, {r['elements']} {kind}, "
        f"{len(r['elements_per_material'])} material(s)",
        f"leaves: {r['leaves_before_balance']} in the tree, "
        f"{r['leaves_after_balance']} after balancing",
    ]
    quality = f"worst radius-to-edge ratio {r['worst_ratio']:.4f}"
    if "min_angle" in r:
        quality += f", angles {r['min_angle']:.2f} to {r.get('max_angle', float('nan')):.2f} deg"
    if "min_dihedral" in r:
        quality += f", dihedral angles {r['min_dihedral']:.2f} to {r['max_dihedral']:.2f} deg"
    lines.append(quality)
    lattice = r.get("lattice")
    if lattice and lattice["cells_per_voxel"] != [1] * r["dim"]:
        cells = " x ".join(str(c) for c in lattice["cells_per_voxel"])
        b = lattice["bounds"]
        lines.append(f"lattice: {cells} cells per voxel (refine {lattice['refine']}, residual "
                     f"aspect {lattice['residual_aspect']:.3f}; bound there: ratio <= "
                     f"{b['worst_ratio']:.4f}, angles {b['min_angle']:.2f} to "
                     f"{b['max_angle']:.2f} deg)")
    if "coarsen" in r:
        c = r["coarsen"]
        changes = ", ".join(f"{m}: {100 * v:+.2f} %" for m, v in c["relative_change"].items())
        lines.append(f"coarsened to 2^{c['level']} voxel blocks: {c['changed_voxels']} voxels "
                     f"changed material; volume change per material {changes}")
    flags = [f"{k} {'ok' if v else 'FAILED'}" for k, v in r["checks"].items()
             if isinstance(v, bool) and k not in ("all_passed", "skipped")]
    lines.append("checks: " + (", ".join(flags) if flags else "skipped (--no-check)"))
    if r.get("frame") == "world":
        lines.append("points in the world frame of the NIfTI affine (--index-space: image frame)")
    total = sum(v for k, v in r["seconds"].items() if k != "mesh_steps")
    lines.append(f"wrote {', '.join(r['output'])} ({total:.2f} s)")
    return "\n".join(lines)


def _run_bounds(args: argparse.Namespace) -> int:
    from .mesher._lattice import aspect_table, choose_lattice, lattice_choices
    from .model._bounds import format_lattice_bounds, format_quality_table, quality_table

    if args.dim not in (2, 3):
        raise ValueError(f"--dim must be 2 or 3; got {args.dim}.")
    if args.max_aspect is not None:
        check_max_aspect(args.max_aspect, "--max-aspect")
        if not args.spacing:
            raise ValueError("--max-aspect picks the lattice for a spacing; give --spacing.")
    lattice = choices = None
    if args.spacing:
        spacing = normalize_spacing(args.spacing, args.dim)
        choices = lattice_choices(spacing)
        lattice = choose_lattice(spacing, max_aspect=args.max_aspect)
    rows, aspects = quality_table(args.dim), aspect_table(args.dim)
    if args.json:
        out = {"command": "bounds", "dim": args.dim, "simplices": rows,
               "by_residual_aspect": aspects}
        if lattice is not None and choices is not None:     # both given by --spacing
            out["lattice"] = lattice.describe()
            out["choices"] = [{**r, "factors": list(r["factors"])} for r in choices]
        print_json(out)
        return 0
    print(format_quality_table(rows))
    print(format_lattice_bounds(args.dim, aspects, lattice, choices))
    return 0
