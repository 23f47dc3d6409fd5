"""Effective conductivity on IMESH meshes against voxel references computed here.

Run:  python benchmarks/bench_simulate.py [--quick] [--skip-speed | --speed-only]
                                         [--scaling [N ...]]

1. Accuracy. Two images whose exact k_eff is not known in closed form:
   - 2-D: 30 % random disks (conductivity 10) in a matrix (1), 96^2 pixels;
   - 3-D: three phases from smoothed noise (1, 10, 0.1: contrast 100): 32^3 blobs of
     sigma 4 (a few voxels thick; the references agree to +-0.2 %) and 24^3 of sigma
     1.5 (phases 1-3 voxels thin; the references stay +-5 % apart).
   The reference is bracketed in this run by two voxel discretisations of the same label
   image, each refined 2x and 4x (every voxel split into r^d) and extrapolated
   (Richardson, rate fitted from the three levels):
   - harmonic two-point finite volumes (cell-centred; converges from below here),
   - P1 on voxel simplices (2 triangles / 6 tetrahedra per voxel; a conforming method,
     so its k_eff lies above the exact one).
   Then, error against the mean of the two extrapolations, and unknowns, for: IMESH with
   the default settings (``order="auto"``: P2 after one adaptive step where the budget
   allows), P1 and P2 without adapting, each also with ``refine=1``; uniform voxel
   simplices P1, voxel quadrilaterals/hexahedra Q1, finite volumes. The default's certified
   interval (issue 26: dual .. primal bound) is printed with whether the reference lies
   in it. The issue's target
   (default within 0.5 % in 2-D, 1 % in 3-D) is printed as MET/MISSED where the
   reference's bracket is tight enough to tell.
2. Speed: a 128^3 three-phase volume, image to k_eff along x, the path
   `swa-imesh simulate` runs: mesh, assembly, solve (iterations), and the whole command in
   a fresh process with its peak memory.
3. Scaling (``--scaling``, :mod:`bench_scaling`): time and peak memory against voxel
   count (32^3, 64^3, 128^3 by default) for the default and the voxel peers in the same
   run, on one material imaged finer, with the fitted exponent of time against voxels.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage, sparse

from bench_pipeline import CHILD  # the whole command in a fresh process, with its peak
from napari_swa_imesh.simulate import simulate
from napari_swa_imesh.simulate._solve import solve_dirichlet

K2D = {1: 1.0, 2: 10.0}
K3D = {1: 1.0, 2: 10.0, 3: 0.1}


def disks(n: int, fraction: float = 0.3, radius: float = 5.5, seed: int = 0) -> np.ndarray:
    """Matrix 1 with random (overlapping) disks 2 until `fraction` of the pixels."""
    rng = np.random.default_rng(seed)
    labels = np.ones((n, n), dtype=np.uint8)
    yy, xx = np.mgrid[:n, :n] + 0.5
    while np.mean(labels == 2) < fraction:
        cy, cx = rng.uniform(0, n, 2)
        labels[(yy - cy) ** 2 + (xx - cx) ** 2 <= radius ** 2] = 2
    return labels


def three_phase(n: int, sigma: float = 2.0, seed: int = 1) -> np.ndarray:
    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal((n,) * 3)
                                .astype(np.float32), sigma)
    return (np.digitize(f, np.quantile(f, [1 / 3, 2 / 3])) + 1).astype(np.uint8)


def refine(labels: np.ndarray, r: int) -> np.ndarray:
    for axis in range(labels.ndim):
        labels = np.repeat(labels, r, axis=axis)
    return labels


def fv_keff(labels: np.ndarray, k: dict, axis: int) -> tuple[float, int]:
    """Two-point flux finite volumes with harmonic face conductivities; unit voxels."""
    cond = np.vectorize(k.get, otypes=[float])(labels)
    n = labels.size
    index = np.arange(n).reshape(labels.shape)
    rows, cols, vals = [], [], []
    diag = np.zeros(n)
    rhs = np.zeros(n)
    for a in range(labels.ndim):
        lo = [slice(None)] * labels.ndim
        hi = [slice(None)] * labels.ndim
        lo[a], hi[a] = slice(None, -1), slice(1, None)
        t = 2 * cond[tuple(lo)] * cond[tuple(hi)] / (cond[tuple(lo)] + cond[tuple(hi)])
        i, j, t = index[tuple(lo)].ravel(), index[tuple(hi)].ravel(), t.ravel()
        rows += [i, j]
        cols += [j, i]
        vals += [-t, -t]
        np.add.at(diag, i, t)
        np.add.at(diag, j, t)
    first = [slice(None)] * labels.ndim
    last = [slice(None)] * labels.ndim
    first[axis], last[axis] = 0, -1
    t0 = 2 * cond[tuple(first)].ravel()            # half a voxel to the face value
    t1 = 2 * cond[tuple(last)].ravel()
    np.add.at(diag, index[tuple(first)].ravel(), t0)
    np.add.at(diag, index[tuple(last)].ravel(), t1)
    rhs[index[tuple(last)].ravel()] += t1 * 1.0
    matrix = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                       np.concatenate(cols))), shape=(n, n))
    matrix = matrix + sparse.diags(diag)
    from napari_swa_imesh.simulate._solve import solve_spd

    u, _ = solve_spd(matrix.tocsr(), rhs, tol=1e-11)
    flux = np.sum(t1 * (1.0 - u[index[tuple(last)].ravel()]))
    shape = np.array(labels.shape, dtype=float)
    return float(flux * shape[axis] / np.prod(np.delete(shape, axis))), n


def voxel_fe_keff(labels: np.ndarray, k: dict, axis: int, kind: str) -> tuple[float, int]:
    """P1 on voxel simplices (kind="simplex") or Q1 on voxels (kind="box"); unit voxels."""
    import skfem
    from skfem.helpers import dot, grad

    coords = [np.arange(s + 1, dtype=float) for s in labels.shape]
    if labels.ndim == 2:
        mesh = skfem.MeshQuad.init_tensor(*coords)
        if kind == "simplex":
            mesh = mesh.to_meshtri()
        elem = skfem.ElementQuad1() if kind == "box" else skfem.ElementTriP1()
    else:
        mesh = skfem.MeshHex.init_tensor(*coords)
        if kind == "simplex":
            mesh = mesh.to_meshtet()
        elem = skfem.ElementHex1() if kind == "box" else skfem.ElementTetP1()
    centre = mesh.p[:, mesh.t].mean(axis=1)                         # (d, M)
    voxel = tuple(np.floor(centre).astype(int))
    kcell = np.vectorize(k.get, otypes=[float])(labels[voxel])
    basis = skfem.Basis(mesh, elem, intorder=2 if kind == "box" else 0)
    field = np.broadcast_to(kcell[:, None], (kcell.size, basis.X.shape[-1]))

    @skfem.BilinearForm
    def form(u, v, w):
        return w["c"] * dot(grad(u), grad(v))

    matrix = skfem.asm(form, basis, c=np.ascontiguousarray(field)).tocsr()
    x = basis.doflocs[axis]
    low = np.flatnonzero(x <= 1e-9)
    high = np.flatnonzero(x >= labels.shape[axis] - 1e-9)
    fixed = np.concatenate([low, high])
    u, _ = solve_dirichlet(matrix, fixed, np.r_[np.zeros(low.size), np.ones(high.size)],
                           tol=1e-11)
    flux = (matrix @ u)[high].sum()
    shape = np.array(labels.shape, dtype=float)
    return float(flux * shape[axis] / np.prod(np.delete(shape, axis))), matrix.shape[0]


def richardson(values: list[float]) -> tuple[float, float]:
    """Extrapolate k(r) for r = 1, 2, 4 assuming k(r) = k* + C r^-p; return (k*, p)."""
    a, b, c = values
    if (a - b) * (b - c) <= 0:
        return c, float("nan")
    p = np.log2((a - b) / (b - c))
    return c - (b - c) / (2 ** p - 1), float(p)


def accuracy_case(name: str, labels: np.ndarray, k: dict, axis: int, quick: bool,
                  target: float) -> None:
    d = labels.ndim
    axis_name = ("z", "y", "x")[-d:][axis]
    print(f"\n## {name}: {'x'.join(map(str, labels.shape))}, k = {k}, along {axis_name}")
    t0 = time.perf_counter()
    levels = (1, 2) if quick else (1, 2, 4)
    fv = [fv_keff(refine(labels, r), k, axis)[0] for r in levels]
    # voxel tetrahedra 4x: 6 * 64 tets per voxel, affordable up to 32^3
    tet_levels = levels if d == 2 or labels.size <= 32 ** 3 else levels[:2]
    tet = [voxel_fe_keff(refine(labels, r), k, axis, "simplex")[0] for r in tet_levels]
    if len(fv) == 3:
        fv_star, fv_p = richardson(fv)
    else:
        fv_star, fv_p = fv[-1], float("nan")
    tet_star, tet_p = richardson(tet) if len(tet) == 3 else (tet[-1], float("nan"))
    reference = 0.5 * (fv_star + tet_star)
    spread = abs(tet_star - fv_star) / reference
    print(f"reference {reference:.6g} (finite volumes {', '.join(f'{v:.6g}' for v in fv)} -> "
          f"{fv_star:.6g}, rate {fv_p:.2f}; voxel simplices "
          f"{', '.join(f'{v:.6g}' for v in tet)} -> {tet_star:.6g}, rate {tet_p:.2f}; "
          f"bracket +-{100 * spread / 2:.2f} %; {time.perf_counter() - t0:.0f} s)")
    print(f"{'discretisation':34s} {'unknowns':>9s} {'k_eff':>10s} {'error %':>8s}")

    def row(label, value, unknowns):
        err = 100 * (value - reference) / reference
        print(f"{label:34s} {unknowns:9d} {value:10.6g} {err:+8.2f}")

    default = simulate(labels, k, axes=axis_name)
    row(f"IMESH default ({default.choice})", default.k_eff[axis_name], default.dofs)
    if default.interval:
        lo, hi = default.interval[axis_name]
        inside = lo <= reference * (1 + spread / 2) and reference * (1 - spread / 2) <= hi
        print(f"  certified interval {lo:.6g} .. {hi:.6g} (gap "
              f"{100 * default.gap[axis_name]:.2f} %): the reference is "
              f"{'inside' if inside else 'OUTSIDE'}"
              + "".join(f"; {w}" for w in default.warnings))
    for order, refine_ in ((1, 0), (2, 0), (1, 1), (2, 1)):
        r = simulate(labels, k, order=order, axes=axis_name, adapt=0, refine=refine_)
        row(f"IMESH P{order}" + (f", refine {refine_}" if refine_ else ""), r.k_eff[axis_name],
            r.dofs)
    for r in (1, 2):
        value, n = voxel_fe_keff(refine(labels, r), k, axis, "simplex")
        row(f"voxel simplices P1, {r}x", value, n)
    for r in (1, 2):
        value, n = voxel_fe_keff(refine(labels, r), k, axis, "box")
        row(f"voxel {'quads' if d == 2 else 'hexahedra'} Q1, {r}x", value, n)
    for r in (1, 2):
        value, n = fv_keff(refine(labels, r), k, axis)
        row(f"finite volumes, {r}x", value, n)
    err = abs(default.k_eff[axis_name] - reference) / reference
    if spread / 2 > target / 2:
        print(f"default within {100 * target:g} %: not measurable here (the reference's "
              f"bracket is +-{100 * spread / 2:.2f} %)")
    else:
        print(f"default within {100 * target:g} %: {'MET' if err <= target else 'MISSED'} "
              f"({100 * err:.2f} %, reference +-{100 * spread / 2:.2f} %)")


def speed(n: int, orders=(1,)) -> None:
    print(f"\n## Speed: {n}^3 three-phase volume (k = {K3D}), image to k_eff along x")
    labels = three_phase(n, sigma=3.0)
    print(f"{'':7s} {'command':>8s} {'peak':>8s} {'mesh':>6s} {'assembly':>8s} "
          f"{'solve':>6s} {'setup':>6s} {'iterate':>7s} {'CG its':>6s} {'elements':>9s} "
          f"{'unknowns':>9s}  k_eff x")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "labels.npy"
        np.save(path, labels)
        for order in orders:
            t0 = time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-c", CHILD, "simulate", str(path), "-k", "1=1", "2=10",
                 "3=0.1", "--axes", "x", "--order", str(order), "--json"],
                capture_output=True, text=True)
            wall = time.perf_counter() - t0
            peak = [ln for ln in proc.stderr.splitlines() if ln.startswith("PEAK ")]
            if proc.returncode != 0 or not peak:
                print(f"P{order}: failed: {proc.stderr[-500:]}")
                continue
            report = json.loads(proc.stdout)
            s = report["seconds"]
            setup = s.get("setup", 0.0)
            # "iterate": the solve less the multigrid set-up (iterations, reactions, fluxes)
            name = f"P{order}" if order != "auto" else f"def(P{report['order']})"
            print(f"{name} {wall:7.1f}s {json.loads(peak[0][5:])['peak'] / 2**30:6.2f}GB "
                  f"{s['mesh']:5.1f}s {s['assemble']:7.1f}s {s['solve']:5.1f}s "
                  f"{setup:5.1f}s {s['solve'] - setup:6.1f}s {report['iterations']['x']:6d} "
                  f"{report['elements']:9d} {report['dofs']:9d}  {report['k_eff']['x']:.10g} "
                  f"(residual {report['residual']:.1e})")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, fewer levels")
    parser.add_argument("--skip-speed", action="store_true")
    parser.add_argument("--speed-only", action="store_true", help="skip the accuracy part")
    parser.add_argument("--size", type=int, default=128, help="edge of the speed volume")
    parser.add_argument("--scaling", type=int, nargs="*", metavar="N",
                        help="only the scaling table, at these edges (default 32 64 128)")
    args = parser.parse_args(argv)
    if args.scaling is not None:
        import bench_scaling

        return bench_scaling.main(["--sizes", *map(str, args.scaling or (32, 64, 128))])
    n2, n3, n3b = (48, 12, 16) if args.quick else (96, 24, 32)
    if not args.speed_only:
        accuracy_case("2-D disks, 30 %, contrast 10", disks(n2), K2D, axis=1,
                      quick=args.quick, target=0.005)
        # blobs a few voxels thick (the resolution issue's case): the references converge
        accuracy_case("3-D three phases (sigma 4), contrast 100", three_phase(n3b, sigma=4.0),
                      K3D, axis=2, quick=args.quick, target=0.01)
        # phases 1-3 voxels thin: the references are still +-5 % apart at 4x
        accuracy_case("3-D three phases (sigma 1.5), contrast 100", three_phase(n3, sigma=1.5),
                      K3D, axis=2, quick=args.quick, target=0.01)
    if not args.skip_speed:
        # P2 at 128^3 would have some 14M unknowns: P1 there, both at 64^3
        speed(64, orders=("auto", 1, 2))
        if not args.quick:
            speed(args.size, orders=("auto", 1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
