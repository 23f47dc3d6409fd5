"""Interface refinement: k_eff error against vertices, beside uniform voxel meshes.

Run:  python benchmarks/bench_refine.py [--size 64] [--quick]

The issue's case: three phases from smoothed noise (sigma 4 voxels: blobs a few voxels
thick; conductivities 1, 10, 0.1, contrast 100), P1 elements, k_eff along x (mixed
protocol). The reference is computed here, independently of the mesher: harmonic
two-point finite volumes on the voxels refined 1x, 2x, 4x and P1 on voxel tetrahedra
(6 per voxel) refined 1x, 2x, 4x, each extrapolated (Richardson, rate fitted) and
averaged; their half-difference is the reference's own uncertainty.

Printed: error and vertices for IMESH P1 at refine K = 0, 1, 2 (meshes, so nothing
adapts), adaptive P1 (Doerfler marking with theta 0.4, 1 and 2 steps; ``order=1`` with
``adapt="auto"``: 2 steps within 2.9x the vertices), P2 at K = 0 and the default (P2 after
one adaptive step), beside uniform voxel tetrahedra (P1) and voxel hexahedra (Q1) at 1x
and 2x; then the issue's target for each P1 route (at most half the K = 0 error within 3x
its vertices: PASS or MISS, with the rate log(error ratio) / log(vertex ratio) it
reached; halving within 3x needs 0.63), and at 64^3 the issue's own figures (<= 3 %
with <= 600k vertices).

Measured on 32^3 (reference +-0.17 %), error against vertices of P1: refine 0 +4.74 %
(26.0k), adapt auto +2.87 % (74.5k, x2.87); Doerfler theta 0.2-0.5 over 1-3 steps, facet
jumps weighted by 1/k (max, arithmetic) or not, and 3 budgeted steps (+2.77 % at x3.01)
all lie on one curve, error about N^-0.5, which halves at about 4x the vertices. Splitting
only the leaves that touch a non-flat interface edge (>= 3 materials or a staircase step
at a lattice edge, where the flux is singular) costs more than refine 1, not less: on
these blobs every interface face has such an edge nearby (64^3: 87.6k non-flat edges
against 77.9k interface faces; K = 1 at those edges 1.50M vertices, refine 1 1.34M).
At 64^3 (reference +-0.05 %): refine 0 +4.70 % (201.7k), adapt auto +2.71 % (583.4k,
x2.89): the issue's <= 3 % with <= 600k is met, its halving within 3x is not (x0.58).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from bench_simulate import K3D, fv_keff, refine, richardson, three_phase, voxel_fe_keff
from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.simulate import simulate
from napari_swa_imesh.simulate._adapt import P1_GROWTH, P1_STEPS, THETA


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64, help="edge of the volume (default 64)")
    parser.add_argument("--sigma", type=float, default=4.0, help="blob scale in voxels")
    parser.add_argument("--quick", action="store_true",
                        help="32^3, references to 2x only (less certain)")
    parser.add_argument("--cache", metavar="JSON",
                        help="keep the reference values in this file and reuse them on the "
                             "next run of the same size, sigma and quickness (the 64^3 "
                             "reference takes most of the run)")
    parser.add_argument("--markdown", metavar="OUT.md",
                        help="also write what is printed to this Markdown page (the docs' "
                             "benchmarks pages include docs/benchmarks/generated/*.md)")
    args = parser.parse_args(argv)
    from _markdown import markdown_page

    n = 32 if args.quick else args.size
    with markdown_page(args.markdown, f"Interface refinement against adaptivity, {n}^3",
                       code=True):
        return _run(args, n)


def _run(args, n: int) -> int:
    labels = three_phase(n, sigma=args.sigma)
    axis, axis_name = 2, "x"
    print(f"## {n}^3 three phases (sigma {args.sigma:g}), k = {K3D}, along {axis_name}")

    t0 = time.perf_counter()
    levels = (1, 2) if args.quick else (1, 2, 4)
    key = f"{n} {args.sigma:g} {'quick' if args.quick else 'full'}"
    cached = _load(args.cache).get(key)
    if cached is None:
        fv = [fv_keff(refine(labels, r), K3D, axis)[0] for r in levels]
        tet = [voxel_fe_keff(refine(labels, r), K3D, axis, "simplex")[0]
               for r in levels[:2] + ((4,) if n <= 32 and not args.quick else ())]
        if args.cache:
            _save(args.cache, {**_load(args.cache), key: {"fv": fv, "tet": tet}})
    else:
        fv, tet = cached["fv"], cached["tet"]
        print(f"(reference values from {args.cache})")
    fv_star = richardson(fv)[0] if len(fv) == 3 else fv[-1]
    tet_star = richardson(tet)[0] if len(tet) == 3 else None
    if tet_star is None:
        # two levels: extrapolate with the rate the finite volumes showed (about 1)
        rate = richardson(fv)[1] if len(fv) == 3 else 1.0
        tet_star = tet[1] - (tet[0] - tet[1]) / (2 ** rate - 1)
    reference = 0.5 * (fv_star + tet_star)
    print(f"reference {reference:.6g} +- {50 * abs(fv_star - tet_star) / reference:.2f} % "
          f"(finite volumes {', '.join(f'{v:.5g}' for v in fv)} -> {fv_star:.5g}; voxel "
          f"tetrahedra {', '.join(f'{v:.5g}' for v in tet)} -> {tet_star:.5g}; "
          f"{time.perf_counter() - t0:.0f} s)\n")

    print(f"{'discretisation':40s} {'vertices':>9s} {'unknowns':>9s} {'error %':>8s} {'s':>6s}")

    def row(name, vertices, unknowns, value, seconds):
        err = 100 * (value - reference) / reference
        print(f"{name:40s} {vertices:9d} {unknowns:9d} {err:+8.2f} {seconds:6.1f}", flush=True)
        return vertices, err

    def imesh(name, **kwargs):
        t = time.perf_counter()
        mesh = kwargs.pop("mesh", None)
        r = simulate(labels if mesh is None else mesh, K3D, axes=axis_name, **kwargs)
        return row(name, len(r.mesh.points), r.dofs, r.k_eff[axis_name], time.perf_counter() - t)

    results = {}
    for k in (0, 1, 2):
        # a mesh, not the labels: nothing adapts (order 1 is asked: the default is P2)
        results[k] = imesh(f"IMESH P1, refine {k}", mesh=mesh_labels(labels, refine=k), order=1)
    for steps in (1, 2):
        results[f"theta{steps}"] = imesh(f"IMESH P1, {steps} Doerfler step{'s' * (steps > 1)} "
                                         f"(theta {THETA:g})", order=1, adapt=steps)
    results["auto"] = imesh(f"IMESH P1, adapt auto ({P1_STEPS} steps, <= {P1_GROWTH:g}x)",
                            order=1)
    imesh("IMESH P2, refine 0", mesh=mesh_labels(labels), order=2)
    imesh("IMESH default (P2, 1 adaptive step)")
    for kind, name in (("simplex", "voxel tetrahedra P1"), ("box", "voxel hexahedra Q1")):
        for r_ in (1, 2):
            t = time.perf_counter()
            value, unknowns = voxel_fe_keff(refine(labels, r_), K3D, axis, kind)
            row(f"{name}, {r_}x", unknowns, unknowns, value, time.perf_counter() - t)

    v0, e0 = results[0]
    print(f"\ntarget: P1 within 3x the vertices of refine 0 ({3 * v0:,}) at half its error "
          f"({abs(e0) / 2:.2f} %) or less")
    for key, name in ((1, "refine 1"), ("theta1", "1 Doerfler step"),
                      ("theta2", "2 Doerfler steps"), ("auto", "adapt auto")):
        v, e = results[key]
        ok = abs(e) <= abs(e0) / 2 and v <= 3 * v0
        rate = np.log(abs(e0) / abs(e)) / np.log(v / v0) if v > v0 and e else float("nan")
        print(f"  {name:18s} error x{abs(e) / abs(e0):.2f}, vertices x{v / v0:.2f}, "
              f"rate {rate:.2f} (halving within 3x needs {np.log(2) / np.log(3):.2f}): "
              f"{'PASS' if ok else 'MISS'}")
    if n == 64:
        v, e = results["auto"]
        ok = abs(e) <= 3.0 and v <= 600_000
        print(f"  the issue's 64^3 figures (<= 3 % with <= 600k vertices), adapt auto: "
              f"{abs(e):.2f} % with {v:,}: {'PASS' if ok else 'MISS'}")
    return 0


def _load(path) -> dict:
    if not path or not os.path.exists(path):
        return {}
    with open(path) as fh:
        return json.load(fh)


def _save(path, values: dict) -> None:
    with open(path, "w") as fh:        # a benchmark's scratch file, not a package output
        json.dump(values, fh, indent=1)


if __name__ == "__main__":
    sys.exit(main())
