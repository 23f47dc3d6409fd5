"""What a reaction-diffusion run reports: tumour volume and front distance per material
over time, the amount's balance, as a table (CSV), a plot (PNG) and the field's time
series (XDMF/HDF5, read by ParaView and meshio's ``TimeSeriesReader``).

The volume above the threshold counts each element whose mean of ``c`` over its vertices
exceeds it (so it is exact to within the elements the front crosses, a band of width
``h``); the front distance of a material is the largest distance from the seed centre of
its elements above the threshold (NaN while none is, or without a seed).
"""

from __future__ import annotations

import csv
import io
from collections import Counter
from pathlib import Path

import numpy as np

from ..io import atomic_write, check_writable
from ..mesh import signed_volumes
from ._growth_steps import BALANCE_TERMS
from ._output import check_series_path, write_series

__all__ = ["growth_outputs", "growth_table", "write_growth"]

#: Default threshold of c for the tumour volume (the travelling wave's midpoint).
DEFAULT_THRESHOLD = 0.5


def growth_table(result, *, threshold: float = DEFAULT_THRESHOLD) -> dict[str, np.ndarray]:
    """Columns over the saved times: ``time``, ``volume_<m>`` and ``front_<m>`` per
    material label ``m``, ``volume``, ``amount``, the balance terms and
    ``balance_residual`` (:func:`write_growth`'s CSV names a material's columns by its
    name where it has one).

    Parameters
    ----------
    result : GrowthResult
    threshold : float
        ``c`` above which an element counts as tumour (0 < threshold < 1).

    Returns
    -------
    dict of str to (T,) ndarray
    """
    if not 0 < threshold < 1:
        raise ValueError(f"threshold must lie between 0 and 1, not {threshold!r}.")
    mesh = result.mesh
    volumes = signed_volumes(mesh.points, mesh.cells)
    means = result.values[:, mesh.cells].mean(axis=2)                  # (T, M)
    above = means > threshold
    table: dict[str, np.ndarray] = {"time": np.asarray(result.times, dtype=float)}
    centroid = mesh.points[mesh.cells].mean(axis=1)
    distance = (np.linalg.norm(centroid - result.seed[0], axis=1)
                if result.seed is not None else np.full(mesh.n_cells, np.nan))
    for m in np.unique(mesh.material):
        own = mesh.material == m
        table[f"volume_{m}"] = (above[:, own] * volumes[own]).sum(axis=1)
        far = np.where(above[:, own], distance[own], -np.inf).max(axis=1, initial=-np.inf)
        table[f"front_{m}"] = np.where(np.isfinite(far), far, np.nan)
    table["volume"] = (above * volumes).sum(axis=1)
    table["amount"] = np.asarray(result.amount, dtype=float)
    for term in BALANCE_TERMS:
        table[term] = np.asarray(result.balance[term], dtype=float)
    table["balance_residual"] = np.asarray(result.balance_residual, dtype=float)
    return table


def growth_outputs(path, *, force: bool = False) -> list[Path]:
    """The files :func:`write_growth` writes for `path` (``.xdmf``, its ``.h5``, the table
    ``<stem>.csv`` and the plot ``<stem>.png``), checked before any work."""
    series = check_series_path(path, force=force)
    p = Path(path)

    return series + [check_writable(p.with_suffix(s), force=force) for s in (".csv", ".png")]


def _csv_columns(materials, names: dict) -> dict[str, str]:
    """The CSV header of :func:`growth_table`'s per-material columns: ``volume_<m>`` ->
    ``volume_<name>`` (likewise ``front_``) for a material with a name, ``<name> (<m>)``
    where two materials would give the same column, the label where it has no name."""
    part = {int(m): str(names.get(int(m), "")).strip() or str(int(m)) for m in materials}
    shared = Counter(part.values())
    part = {m: p if shared[p] == 1 or p == str(m) else f"{p} ({m})" for m, p in part.items()}
    if len(set(part.values())) < len(part):          # a name such as "x (3)" beside two x
        part = {m: str(m) for m in part}
    return {f"{prefix}_{m}": f"{prefix}_{p}" for m, p in part.items()
            for prefix in ("volume", "front")}


def _csv_text(table: dict[str, np.ndarray], header: dict[str, str]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow([header.get(key, key) for key in table])
    for row in zip(*table.values()):
        writer.writerow(["" if not np.isfinite(v) else f"{float(v):.10g}" for v in row])
    return out.getvalue()


def _plot(table: dict[str, np.ndarray], path: Path, names: dict, threshold: float) -> None:
    """The volume and the front's distance per material over time, side by side."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4), dpi=100)
    volume, front = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for key in table:
        for prefix, ax in (("volume_", volume), ("front_", front)):
            if key.startswith(prefix):
                label = key.removeprefix(prefix)
                ax.plot(table["time"], table[key], marker=".",
                        label=str(names.get(int(label), f"material {label}")))
    volume.plot(table["time"], table["volume"], color="k", lw=2, label="all")
    volume.set_ylabel(f"volume with c > {threshold:g}")
    front.set_ylabel("front's distance from the seed")
    for ax in (volume, front):
        ax.set_xlabel("time")
        ax.legend(loc="upper left")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, format="png")


def write_growth(result, path, *, threshold: float = DEFAULT_THRESHOLD,
                 force: bool = False) -> list[Path]:
    """Write the time series, the table and the plot of a :class:`GrowthResult`, all or
    none.

    Parameters
    ----------
    result : GrowthResult
    path : str or Path
        The ``.xdmf`` of the series (field ``c``); the ``.h5`` beside it, the table
        ``<stem>.csv`` (:func:`growth_table`'s columns, a material's named by its name
        where it has one: ``volume_white matter``, else by its label: ``volume_3``; by
        ``white matter (3)`` where two materials share a name) and the volume curve
        ``<stem>.png``.
    threshold : float
        As for :func:`growth_table`.
    force : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The files written.
    """
    targets = growth_outputs(path, force=force)
    table = growth_table(result, threshold=threshold)
    with atomic_write(targets, force=force) as temps:
        # the series' own writer, into the temporary folder (its files keep their names)
        write_series(result, temps[0], force=True, name="c")
        names = dict(result.mesh.material_names)
        header = _csv_columns(np.unique(result.mesh.material), names)
        temps[2].write_text(_csv_text(table, header), encoding="utf-8")
        _plot(table, temps[3], names, threshold)
    return targets
