"""Anisotropic voxels: elements, quality bound and memory against isotropic (issue 22).

Run:  python benchmarks/bench_anisotropy.py [--big] [--old]

Cases, each in a fresh process that reports its own peak RSS (``VmHWM``):

* a brain label volume of 99 x 117 x 95 voxels (nilearn's MNI152 grey/white-matter maps
  and brain mask at 2 mm: background, CSF, GM, WM by the most probable tissue; a smooth
  random 3-material volume of that shape when nilearn is missing) meshed with
  ``mesh_labels`` at spacing 1 (the reference), 0.9375 x 0.9375 x 1.5 and 0.9 x 1.1 x 2.0:
  elements against isotropic, the lattice, the bound the lattice proves
  (``aspect_bounds`` at its residual aspect) and the worst quality of the elements,
  recomputed from their points (radius-to-edge, dihedral angles);
* ``--old``: the same at the former limit ``max_aspect=1.2`` (0.9375 x 0.9375 x 1.5 only:
  0.9 x 1.1 x 2.0 takes 84 cells per voxel there and needs about 24 GB);
* a 40 x 50 x 30 NIfTI of smooth 3-material blobs with float32 zooms 1 / 0.8 / 1.2: the
  whole ``swa-imesh mesh``, ``swa-imesh simulate --order 1`` (default adapt, whose vertex
  budget counts from the labels on voxel cells) and fully default ``simulate`` commands,
  and the same labels isotropic;
* ``--big``: a 256^3 blob volume at 0.9375 x 0.9375 x 1.5 (``swa-imesh mesh --no-check``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from _peak import PEAK_SOURCE

SPACINGS = {"isotropic": (1.0, 1.0, 1.0), "0.9375x0.9375x1.5": (0.9375, 0.9375, 1.5),
            "0.9x1.1x2.0": (0.9, 1.1, 2.0)}

MESH_CHILD = PEAK_SOURCE + """
import json, sys, time
import numpy as np
from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.mesh.model._quality import dihedral_angles, radius_edge_ratio
lab = np.load(sys.argv[1])
spacing = tuple(json.loads(sys.argv[2]))
max_aspect = json.loads(sys.argv[3])
t = time.perf_counter()
mesh = mesh_labels(lab, spacing=spacing, max_aspect=max_aspect)
seconds = time.perf_counter() - t
ratio = radius_edge_ratio(mesh.points, mesh.cells)
lo, hi = dihedral_angles(mesh.points, mesh.cells)
lattice = mesh.recipe.lattice.describe()
print(json.dumps({"elements": int(mesh.n_cells), "factors": lattice["factors"],
                  "residual_aspect": lattice["residual_aspect"], "bound": lattice["bounds"],
                  "worst_ratio": float(ratio.max()), "min_dihedral": float(lo.min()),
                  "max_dihedral": float(hi.max()), "seconds": seconds,
                  "peak": peak_bytes()}))
"""

CLI_CHILD = PEAK_SOURCE + """
import json, sys, time, contextlib, io
from napari_swa_imesh.cli import main
t = time.perf_counter()
out = io.StringIO()
with contextlib.redirect_stdout(out):
    rc = main(sys.argv[1:])
print(json.dumps({"rc": rc, "seconds": time.perf_counter() - t, "out": out.getvalue(),
                  "peak": peak_bytes()}))
"""


def brain_labels() -> tuple[np.ndarray, str]:
    """(99, 117, 95) labels 0 background, 1 CSF, 2 GM, 3 WM, and where they came from."""
    try:
        sys.path.insert(0, str(Path(__file__).parent))
        from anatomy import template

        gm, wm, brain = template()                      # (z, y, x) 189 x 233 x 197, 1 mm
    except (ImportError, OSError, ValueError):          # nilearn missing: a stand-in
        return blobs((99, 117, 95), seed=7), "smooth random 3-material blobs"
    prob = np.stack([1 - brain, brain * np.clip(1 - gm - wm, 0, 1), brain * gm, brain * wm])
    labels = prob.argmax(axis=0).astype(np.uint8)[::2, ::2, ::2]   # 2 mm: 95 x 117 x 99
    return np.ascontiguousarray(labels.transpose(2, 1, 0)), "MNI152 tissue maps at 2 mm"


def blobs(shape, seed: int = 1) -> np.ndarray:
    """Three materials from smoothed noise (sigma about 1/13 of each axis)."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    f = ndimage.gaussian_filter(rng.random(shape, dtype=np.float32),
                                [n / 13 for n in shape])
    return np.digitize(f, np.quantile(f, [0.4, 0.7])).astype(np.uint8)


def run(code: str, *args) -> dict:
    proc = subprocess.run([sys.executable, "-c", code, *map(str, args)],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-1:] or ["(no message)"]
        return {"error": tail[0]}
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["stderr"] = (proc.stderr.strip().splitlines() or [""])[-1]
    return out


def mesh_rows(labels: np.ndarray, folder: Path, old: bool) -> list[dict]:
    path = folder / "brain.npy"
    np.save(path, labels)
    rows = []
    cases = [(name, s, None) for name, s in SPACINGS.items()]
    if old:
        cases.append(("0.9375x0.9375x1.5 (old 1.2)", SPACINGS["0.9375x0.9375x1.5"], 1.2))
    for name, spacing, limit in cases:
        r = run(MESH_CHILD, path, json.dumps(spacing), json.dumps(limit))
        rows.append({"case": name, **r})
    return rows


def print_mesh_table(rows: list[dict], source: str, shape) -> None:
    print(f"\nbrain-like {'x'.join(map(str, shape))} ({source}), mesh_labels defaults")
    print(f"{'spacing':28s} {'cells':>9s} {'elements':>10s} {'x iso':>6s} {'bound ratio':>11s}"
          f" {'bound dihedral':>15s} {'worst ratio':>11s} {'dihedral':>15s} {'s':>6s}"
          f" {'peak MB':>8s}")
    iso = next((r["elements"] for r in rows if r["case"] == "isotropic" and "elements" in r),
               None)
    for r in rows:
        if "error" in r:
            print(f"{r['case']:28s} failed: {r['error']}")
            continue
        cells = "x".join(map(str, r["factors"]))
        b = r["bound"]
        print(f"{r['case']:28s} {cells:>9s} {r['elements']:10d} "
              f"{r['elements'] / iso if iso else float('nan'):6.2f} {b['worst_ratio']:11.4f} "
              f"{b['min_angle']:6.2f}..{b['max_angle']:6.2f} {r['worst_ratio']:11.4f} "
              f"{r['min_dihedral']:6.2f}..{r['max_dihedral']:6.2f} {r['seconds']:6.1f} "
              f"{r['peak'] / 2**20:8.0f}")


def float32_rows(folder: Path) -> list[dict]:
    import nibabel as nib

    labels = blobs((40, 50, 30), seed=3)
    img = nib.Nifti1Image(labels, np.diag([1.0, 0.8, 1.2, 1.0]))
    img.header.set_zooms((1.0, 0.8, 1.2))              # stored as float32: 0.800000011920929
    nii = folder / "f32.nii.gz"
    nib.save(img, nii)
    np.save(folder / "f32.npy", labels)
    k = ["-k", "0=1", "1=10", "2=100"]
    rows = []
    for name, src in (("zooms 1/0.8/1.2 float32", nii), ("isotropic", folder / "f32.npy")):
        for command in (["mesh", src, "-o", folder / "m.vtu", "--force", "--json"],
                        ["simulate", src, *k, "--order", "1", "--json"],
                        ["simulate", src, *k, "--json"]):
            r = run(CLI_CHILD, *command)
            info = {}
            if r.get("rc") == 0:
                out = json.loads(r["out"])
                info = {"elements": out.get("elements", out.get("n_cells")),
                        "factors": (out.get("lattice") or {}).get("factors")}
                if command[0] == "simulate":
                    info["unknowns"] = out.get("dofs")
            label = command[0] + (" P1" if "--order" in command else " default"
                                  if command[0] == "simulate" else "")
            rows.append({"case": name, "command": label, **r, **info})
    return rows


def print_float32_table(rows: list[dict]) -> None:
    print("\n40x50x30 NIfTI, zooms 1 / 0.8 / 1.2 as float32 (the whole command; simulate "
          "--order 1 with default adapt, and the full default)")
    print(f"{'labels':26s} {'command':16s} {'rc':>3s} {'elements':>10s} {'unknowns':>9s}"
          f" {'s':>7s} {'peak MB':>8s}")
    for r in rows:
        if "error" in r or r.get("rc") != 0:
            print(f"{r['case']:26s} {r['command']:16s} failed: "
                  f"{r.get('error') or r.get('stderr')}")
            continue
        print(f"{r['case']:26s} {r['command']:16s} {r['rc']:3d} {r.get('elements')!s:>10}"
              f" {r.get('unknowns', '')!s:>9} {r['seconds']:7.1f} {r['peak'] / 2**20:8.0f}")


def big_row(folder: Path) -> None:
    labels = blobs((256, 256, 256), seed=5)
    np.save(folder / "big.npy", labels)
    del labels
    r = run(CLI_CHILD, "mesh", folder / "big.npy", "-o", folder / "big.vtu", "--spacing",
            "0.9375", "0.9375", "1.5", "--no-check", "--json")
    print("\n256^3 blobs at 0.9375 x 0.9375 x 1.5 (swa-imesh mesh --no-check)")
    if "error" in r or r.get("rc") != 0:
        print(f"failed: {r.get('error') or r.get('stderr')}")
        return
    out = json.loads(r["out"])
    print(f"elements {out['elements']}, lattice {out['lattice']['factors']}, "
          f"worst ratio {out['worst_ratio']:.4f}, {r['seconds']:.1f} s, "
          f"peak {r['peak'] / 2**30:.2f} GB")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--big", action="store_true", help="also mesh a 256^3 volume")
    parser.add_argument("--old", action="store_true", help="also the former limit 1.2")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        labels, source = brain_labels()
        print_mesh_table(mesh_rows(labels, folder, args.old), source, labels.shape)
        print_float32_table(float32_rows(folder))
        if args.big:
            big_row(folder)
    return 0


if __name__ == "__main__":
    sys.exit(main())
