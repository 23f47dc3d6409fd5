"""IMESH benchmark: template vs the reference's Delaunay step, speed, memory and counts.

Run:  python benchmarks/bench_mesh.py [--quick]

Every case runs in its own process so that peak memory (``ru_maxrss``) is the case's own.
Cases:

1. 2-D: a 1024^2 label image of nested noisy shells (template, and Delaunay on the same
   image).
2. 3-D: a 256^3 brain-like label volume (nested shells: background, scalp, skull, CSF, grey
   and white matter; boundaries roughened by noise at 2-16 voxel scales plus isolated
   voxels). Template with the face+edge balance it needs, and with full (corner) balance
   for the element cost; the face-only balance's leaf count is printed too.
3. 3-D Delaunay (scipy's Qhull on the leaf corners) on a 64^3 volume of the same kind,
   beside the template on that volume: at 256^3 Qhull would need hours and many GB, so it
   is compared at the size it can do; its zero-volume count and conformity are printed.

With ``--pipeline`` it measures instead the way to a file at volume size (the brain-like
256^3 volume, or ``--shape``): the tree alone, the mesher alone (tree + mesh), the checks,
the facet groups and each writer, each in its own process (time of the step, peak RSS of
the process), then ``swa-imesh mesh LABELS.npy -o out.SUFFIX`` per format as a
subprocess (wall time and its peak RSS), with the goals as ratios to the mesher.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np


def brain_like(n: int, dim: int, seed: int = 0) -> np.ndarray:
    """Nested noisy shells, labels 0 (background) .. 5 (white matter), shape (n,) * dim."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    axes = np.ogrid[tuple(slice(0, n) for _ in range(dim))]
    semi = np.array([0.50, 0.44, 0.48][:dim]) * n
    r = np.sqrt(sum(((a + 0.5 - n / 2) / s) ** 2 for a, s in zip(axes, semi))).astype(np.float32)
    rough = np.zeros((n,) * dim, np.float32)
    for cells, amp in ((4, 0.06), (16, 0.025), (64, 0.012)):
        coarse = rng.standard_normal((min(cells, n),) * dim).astype(np.float32)
        rough += amp * ndimage.zoom(coarse, n / coarse.shape[0], order=1)[
            tuple(slice(0, n) for _ in range(dim))]
    r += rough
    del rough
    labels = np.digitize(r, [0.45, 0.62, 0.75, 0.82, 0.92]).astype(np.uint8)
    labels = (5 - labels).astype(np.uint8)  # 0 outside ... 5 at the centre
    # isolated voxels of a neighbouring tissue (segmentation noise)
    spots = rng.random(labels.shape, dtype=np.float32) < 2e-4
    labels[spots] = np.minimum(labels[spots] + 1, 5)
    return labels


def run_one(spec: dict) -> dict:
    """Mesh one case in this process and return its figures."""
    from napari_swa_imesh import build_tree
    from napari_swa_imesh.mesh.checks._checks import check_mesh
    from napari_swa_imesh.mesh.mesher._imesh import mesh_tree

    labels = brain_like(spec["n"], spec["dim"], seed=spec.get("seed", 0))
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    c0 = time.process_time()
    tree = build_tree(labels)
    tree_seconds = time.perf_counter() - t0
    mesh = mesh_tree(tree, method=spec["method"], connectivity=spec.get("connectivity"),
                     report_face_balance=True)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    info = dict(mesh.info)
    info["seconds"] = {"tree": tree_seconds, **info["seconds"]}
    info["seconds_total"] += tree_seconds
    if spec["method"] == "delaunay":  # reported as it is, outside the timing
        info["conforming"] = check_mesh(mesh, labels, tree=tree).conforming
    out = {
        **spec,
        "wall": wall,
        "cpu": cpu,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "input_rss_mb": base_rss / 1024,
        "info": info,
    }
    if spec.get("check"):
        t = time.perf_counter()
        checks = check_mesh(mesh, labels)
        out["check_seconds"] = time.perf_counter() - t
        out["checks_passed"] = bool(checks["all_passed"])
        out["checks"] = {k: v for k, v in checks.items() if isinstance(v, bool)}
    return out


#: goals of the path to a file, as ratios to the mesher alone (same run)
PIPELINE_GOALS = {"checks": 1.0, ".vtu": 1.0, "command_time": 5.0, "command_memory": 1.5}
PIPELINE_FORMATS = (".vtu", ".inp", ".msh", ".xdmf")


def pipeline_step(spec: dict) -> dict:
    """One step of the path to a file in this process: seconds of the step, peak RSS."""
    from napari_swa_imesh.mesh.mesher._imesh import _mesh_labels

    labels = np.load(spec["labels"])
    step, extra = spec["step"], {}
    t, cpu = time.perf_counter(), time.process_time()
    if step == "tree":
        from napari_swa_imesh import build_tree

        build_tree(labels)
    else:
        mesh, tree = _mesh_labels(labels, method="template", exclude=np.zeros(0, np.int64),
                                  spacing=(1.0,) * labels.ndim)
        extra = {"elements": mesh.n_cells, "vertices": len(mesh.points)}
        if step != "mesher":  # the mesher row times tree + mesh; the others their step
            t, cpu = time.perf_counter(), time.process_time()
        if step == "checks":
            from napari_swa_imesh.mesh.checks._checks import check_mesh

            extra["passed"] = check_mesh(mesh, labels, tree=tree).all_passed
        elif step == "facet groups":
            from napari_swa_imesh.mesh import facet_groups

            extra["groups"] = len(facet_groups(mesh))
        elif step != "mesher":
            from napari_swa_imesh.mesh.formats._export import write_mesh

            del tree
            write_mesh(mesh, spec["out"], force=True)
    return {"seconds": time.perf_counter() - t, "cpu": time.process_time() - cpu,
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, **extra}


def pipeline_command(spec: dict) -> dict:
    """``swa-imesh mesh`` as the user runs it, in a child process: wall time, peak RSS."""
    t = time.perf_counter()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run([sys.executable, "-m", "napari_swa_imesh.cli", "mesh", spec["labels"],
                          "-o", spec["out"], "--force", "--json"], capture_output=True, text=True,
                         check=False)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    out = {"seconds": wall, "cpu": cpu,
           "peak_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
           "exit": res.returncode}
    if res.returncode in (0, 1):
        report = json.loads(res.stdout)
        out["steps"] = {k: round(v, 2) for k, v in report["seconds"].items() if k != "mesh_steps"}
        out["passed"] = report["checks"].get("all_passed")
    else:
        out["error"] = res.stderr.strip().splitlines()[-1] if res.stderr else "failed"
    return out


def run_pipeline(shape: tuple, folder: str, formats=PIPELINE_FORMATS) -> None:
    import os

    n = max(shape)
    labels = brain_like(n, len(shape))[tuple(slice((n - k) // 2, (n - k) // 2 + k) for k in shape)]
    path = os.path.join(folder, "labels.npy")
    np.save(path, labels)

    def step(name):
        spec = {"step": name, "labels": path, "out": os.path.join(folder, "step" + name)}
        return _spawn_json(["--pipeline-step", json.dumps(spec)])

    rows = {"tree": step("tree"), "mesher": step("mesher")}
    mesher = rows["mesher"]
    print(f"\n{'x'.join(map(str, shape))}: {mesher.get('elements')} elements, "
          f"{mesher.get('vertices')} vertices; ratios to the mesher alone\n")
    print("| step | seconds | CPU s | peak RSS MB | time / mesher | goal | CPU / mesher | goal "
          "(CPU) | memory / mesher | notes |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    names = ["tree", "mesher", "checks", "facet groups", *formats,
             *("command " + f for f in formats)]
    for name in names:
        if name not in rows:
            if name.startswith("command "):
                spec = {"labels": path, "out": os.path.join(folder, "command" + name[8:])}
                rows[name] = _spawn_json(["--pipeline-command", json.dumps(spec)])
            else:
                rows[name] = step(name)
        print(_pipeline_row(name, rows[name], rows), flush=True)
    print("\nstep rows: seconds of the step alone (the mesher row: tree + mesh) in a process "
          "that read the labels and meshed first, so their peak RSS includes the mesher's. "
          "command rows: wall time of the whole command (interpreter start, read, mesh, "
          "check, write) and its peak RSS; x tree: the same time over the tree alone.")


def _pipeline_row(name: str, r: dict, rows: dict) -> str:
    if "error" in r or "error" in rows["mesher"]:
        return f"| {name} | error: {r.get('error', rows['mesher'].get('error'))} ||||||||"
    mesher = rows["mesher"]
    ratio, mem = r["seconds"] / mesher["seconds"], r["peak_mb"] / mesher["peak_mb"]
    # CPU seconds: what a loaded, shared machine does not move (wall time it does)
    cpu_ratio = r["cpu"] / mesher["cpu"]
    goal, cpu_goal, notes = "", "", ""
    if name in ("checks", ".vtu"):
        g = PIPELINE_GOALS[name]
        goal = f"<= {g:g}: {'PASS' if ratio <= g else 'MISS'}"
        cpu_goal = f"{'PASS' if cpu_ratio <= g else 'MISS'}"
    elif name.startswith("command"):
        gt, gm = PIPELINE_GOALS["command_time"], PIPELINE_GOALS["command_memory"]
        goal = (f"time <= {gt:g}: {'PASS' if ratio <= gt else 'MISS'}; memory <= {gm:g}: "
                f"{'PASS' if mem <= gm else 'MISS'}")
        cpu_goal = f"{'PASS' if cpu_ratio <= gt else 'MISS'}"
        notes = f"{r['seconds'] / rows['tree']['seconds']:.0f} x tree; steps {r.get('steps')}"
    if "passed" in r:
        notes += f" checks {'pass' if r['passed'] else 'FAIL'}"
    return (f"| {name} | {r['seconds']:.2f} | {r['cpu']:.2f} | {r['peak_mb']:.0f} | "
            f"{ratio:.2f} | {goal} | {cpu_ratio:.2f} | {cpu_goal} | {mem:.2f} | "
            f"{notes.strip()} |")


def _spawn_json(args: list) -> dict:
    res = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True,
                         check=False)
    if res.returncode:
        return {"error": res.stderr.strip().splitlines()[-1] if res.stderr else "failed"}
    return json.loads(res.stdout.strip().splitlines()[-1])


def _spawn(spec: dict) -> dict:
    res = subprocess.run([sys.executable, __file__, "--one", json.dumps(spec)],
                         capture_output=True, text=True, check=False)
    if res.returncode:
        return {**spec, "error": res.stderr.strip().splitlines()[-1] if res.stderr else "failed"}
    return json.loads(res.stdout.strip().splitlines()[-1])


def _row(r: dict) -> str:
    shape = "x".join([str(r["n"])] * r["dim"])
    if "error" in r:
        return f"| {shape} | {r['method']} | error: {r['error']} |"
    i = r["info"]
    s = i["seconds"]
    el = i["n_elements"]
    steps = " / ".join(f"{s.get(k, 0):.2f}" for k in ("tree", "balance", "vertices", "simplices",
                                                       "numbering", "quality"))
    total = i["seconds_total"] - s.get("face_balance_count", 0.0)
    angles = "-".join(f"{a:.1f}" for a in i["angle_range"])
    extra = ""
    if r["method"] == "delaunay":
        extra = (f"zero-vol {i['n_zero_volume']} of {i['n_delaunay_simplices']}, "
                 f"conforming {i['conforming']}")
    elif "checks_passed" in r:
        extra = (f"all checks {'pass' if r['checks_passed'] else 'FAIL'} "
                 f"({r['check_seconds']:.1f} s)")
    return (f"| {shape} | {r['method']} | {i['balance']} | {i['n_leaves_tree']} / "
            f"{i['n_leaves_face_balanced']} / {i['n_leaves_balanced']} | {i['n_vertices']} | "
            f"{el} | {el / max(1, i['n_leaves_meshed']):.2f} | {steps} | {total:.2f} | "
            f"{r['cpu']:.2f} | {el / total / 1e6:.2f} | {r['peak_rss_mb']:.0f} | "
            f"{i['worst_ratio']:.4f} | {angles} | {extra} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only (smoke run)")
    parser.add_argument("--only", type=int, nargs="*", help="run only these case numbers (0-5)")
    parser.add_argument("--pipeline", action="store_true",
                        help="time the way to a file (tree, mesher, checks, facet groups, "
                             "writers, whole command per format) instead")
    parser.add_argument("--shape", type=int, nargs="+", default=None,
                        help="shape of the --pipeline volume (default 256 256 256)")
    parser.add_argument("--formats", nargs="+", default=list(PIPELINE_FORMATS),
                        help="suffixes written by --pipeline (default: .vtu .inp .msh .xdmf)")
    parser.add_argument("--markdown", metavar="OUT.md",
                        help="also write the tables to this Markdown page (the docs' "
                             "benchmarks pages include docs/benchmarks/generated/*.md)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--pipeline-step", help=argparse.SUPPRESS)
    parser.add_argument("--pipeline-command", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(json.loads(args.one)), default=float))
        return 0
    if args.pipeline_step or args.pipeline_command:
        run = pipeline_step if args.pipeline_step else pipeline_command
        print(json.dumps(run(json.loads(args.pipeline_step or args.pipeline_command)),
                         default=float))
        return 0
    from _markdown import markdown_page

    title = "IMESH " + ("pipeline" if args.pipeline else "template vs Delaunay") + (
        ", quick sizes" if args.quick else "")
    with markdown_page(args.markdown, title):
        return _tables(args)


def _tables(args) -> int:
    if args.pipeline:
        import tempfile

        shape = tuple(args.shape or ((64,) * 3 if args.quick else (256,) * 3))
        with tempfile.TemporaryDirectory() as folder:
            run_pipeline(shape, folder, tuple(args.formats))
        return 0
    n2, n3, nd = (256, 64, 32) if args.quick else (1024, 256, 64)
    specs = [
        {"dim": 2, "n": n2, "method": "template"},
        {"dim": 2, "n": n2, "method": "delaunay"},
        {"dim": 3, "n": n3, "method": "template"},
        {"dim": 3, "n": n3, "method": "template", "connectivity": 3},
        {"dim": 3, "n": nd, "method": "template", "check": True},
        {"dim": 3, "n": nd, "method": "delaunay"},
    ]
    print("| shape | method | balance | leaves: tree / face-balanced / balanced | vertices | "
          "elements | el./leaf | s: tree / balance / vertices / simplices / numbering / quality "
          "| s total | CPU s | M el./s | peak RSS MB | worst R/e | angles deg | notes |")
    print("|" + "---|" * 15)
    for k, spec in enumerate(specs):
        if args.only is None or k in args.only:
            print(_row(_spawn(spec)), flush=True)
    print("\nangles: min-max interior angle (2-D) or dihedral angle (3-D). s total: wall seconds "
          "of the meshing steps (tree to per-element data), without the face-only balance count "
          "made for the report; CPU s: process time of the whole call including that count "
          "(the code is single-threaded, so CPU s well below s total means the process waited "
          "for a core on a shared machine). Peak RSS is the whole process (Python, "
          "numpy, the label volume and the mesh). Delaunay 3-D runs at 64^3 only: Qhull on the "
          "256^3 corners would take hours.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
