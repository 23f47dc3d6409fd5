"""The pictures of docs/growth.md: a glioma growing in the bundled tissue phantom.

Run from the repository::

    python docs/growth_figures.py [--no-3d | --only-3d]

It takes the middle plane of :func:`napari_swa_imesh.data.tissue_phantom` (1 mm pixels;
1 CSF, 2 grey matter, 3 white matter), grows a Fisher-KPP tumour from a seed in the white
matter with D = 0.1 mm^2/day in white matter, 0.02 in grey (5x, the standard glioma model),
none in CSF, rho = 0.012/day, for 720 days with a temozolomide-like kill rate 0.01/day over
days 360..420, and writes the front at three times and the volume curve to ``docs/images/``
(palette-quantised PNGs) with the run's figures printed. Then the same model on the 3-D
phantom (coarser: one element per front width) for its run time.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.simulate import growth_table, simulate_growth

OUT = Path(__file__).resolve().parent / "images"
D = {2: 0.02, 3: 0.1}                     # grey, white matter (mm^2/day); CSF: none
RATE = 0.012                              # per day
KILL = [(360.0, 420.0, 0.01)]             # a chemotherapy cycle (per day)
DURATION = 720.0


def _quantised(fig, path: Path) -> None:
    from io import BytesIO

    from PIL import Image

    buffer = BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    Image.open(buffer).convert("RGB").quantize(colors=128).save(path, optimize=True)


def _deepest(mask: np.ndarray, spacing) -> tuple[float, ...]:
    """x, y(, z) of the centre of the voxel deepest inside `mask` (a seed in white matter)."""
    from scipy import ndimage

    depth = ndimage.distance_transform_edt(mask, sampling=spacing)
    index = np.unravel_index(int(np.argmax(depth)), mask.shape)
    return tuple(float((i + 0.5) * s) for i, s in zip(index, spacing))[::-1]


def slice_run():
    _, truth = tissue_phantom((64, 96, 96), spacing=(2.0, 1.0, 1.0), seed=0)
    labels = truth[32]                                               # (96, 96), 1 mm
    seed = (_deepest(labels == 3, (1.0, 1.0)), 5.0)                  # x, y (mm)
    t0 = time.perf_counter()
    result = simulate_growth(labels, D, rate=RATE, seed=seed, kill=KILL,
                             duration=DURATION, saves=24, spacing=(1.0, 1.0))
    seconds = time.perf_counter() - t0
    return labels, result, seconds


def front_figure(labels, result, path: Path) -> None:
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch
    from matplotlib.tri import Triangulation

    mesh = result.mesh
    tissue = ListedColormap(["black", "#9ecae1", "#bdbdbd", "#f7f7f7"])   # -, CSF, GM, WM
    fig = Figure(figsize=(10, 3.9))
    picks = [int(np.argmin(np.abs(result.times - t))) for t in (240.0, 480.0, 720.0)]
    extent = (0, labels.shape[1], labels.shape[0], 0)
    for i, k in enumerate(picks):
        ax = fig.add_subplot(1, 3, i + 1)
        ax.imshow(labels, cmap=tissue, extent=extent, vmin=-0.5, vmax=3.5,
                  interpolation="nearest")
        values = result.values[k]
        tri = Triangulation(mesh.points[:, 1], mesh.points[:, 0], mesh.cells)
        tri.set_mask(values[mesh.cells].max(axis=1) < 0.02)       # the tissue shows there
        shown = ax.tripcolor(tri, values, cmap="magma", vmin=0, vmax=1, shading="gouraud")
        ax.tricontour(tri, values, levels=[0.5], colors="cyan", linewidths=1)
        ax.set_title(f"t = {result.times[k]:g} days")
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(shown, ax=fig.axes, label="tumour cell density c", shrink=0.8)
    fig.legend(handles=[Patch(color=c, label=n) for c, n in
                        (("#9ecae1", "CSF (D = 0)"), ("#bdbdbd", "grey matter"),
                         ("#f7f7f7", "white matter"))],
               loc="lower center", ncol=3, frameon=False)
    _quantised(fig, path)


def volume_figure(result, path: Path) -> None:
    from matplotlib.figure import Figure

    table = growth_table(result)
    fig = Figure(figsize=(6, 3.6))
    ax = fig.add_subplot(1, 1, 1)
    for m, name in ((3, "white matter"), (2, "grey matter")):
        ax.plot(table["time"], table[f"volume_{m}"], marker=".", label=name)
    ax.plot(table["time"], table["volume"], color="k", lw=2, label="all")
    for a, b, _ in KILL:
        ax.axvspan(a, b, color="tab:green", alpha=0.15, label="kill 0.01/day")
    ax.set_xlabel("time (days)")
    ax.set_ylabel("area with c > 0.5 (mm$^2$)")
    ax.legend(loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _quantised(fig, path)


def main() -> int:
    if "--only-3d" not in sys.argv:
        _slice()
    if "--no-3d" not in sys.argv:
        _three_d()
    return 0


def _slice() -> None:
    labels, result, seconds = slice_run()
    print(result.describe())
    print(f"slice: {seconds:.1f} s, {result.mesh.n_cells} elements, "
          f"max element/bound {result.size['max_ratio']:.2f}")
    table = growth_table(result)
    for k in range(0, len(result.times), 6):
        print(f"t = {table['time'][k]:5g}: area {table['volume'][k]:8.2f} mm^2, front "
              f"WM {table['front_3'][k]:.2f} mm, GM {table['front_2'][k]:.2f} mm")
    front_figure(labels, result, OUT / "growth_front.png")
    volume_figure(result, OUT / "growth_volume.png")


def _three_d() -> None:
    _, truth = tissue_phantom((32, 48, 48), spacing=(2.0, 2.0, 2.0), seed=0)
    t0 = time.perf_counter()
    three = simulate_growth(truth, D, rate=RATE,
                            seed=(_deepest(truth == 3, (2.0, 2.0, 2.0)), 6.0),
                            duration=360.0, saves=6, spacing=(2.0, 2.0, 2.0),
                            front_cells=1.0)
    print(three.describe())
    table3 = growth_table(three)
    print("3-D volume (mm^3):", np.round(table3["volume"], 1).tolist())
    print("3-D front WM / GM (mm):", np.round(table3["front_3"], 2).tolist(),
          np.round(table3["front_2"], 2).tolist())
    print(f"3-D phantom {truth.shape}: {time.perf_counter() - t0:.1f} s, "
          f"{three.mesh.n_cells} elements, max element/bound "
          f"{three.size['max_ratio']:.2f}")


if __name__ == "__main__":
    sys.exit(main())
