"""The result of a stochastic k_eff run: statistics, the sample table and the histogram.

Statistics per axis over the N samples: the mean, the standard deviation (``ddof=1``),
the interval holding the central 95 % of the samples (the 2.5 and 97.5 percentiles),
and the Monte-Carlo standard error of the mean, ``std / sqrt(N)``.

Files: the sample table (``.csv``: a ``sample`` column, then ``k_eff_<axis>``), the
histogram (``.png``, ``.pdf`` or ``.svg``), both written through :func:`~..io.atomic_write`.
"""

from __future__ import annotations

import io as _io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io import atomic_write, check_writable

__all__ = ["FIGURE_SUFFIXES", "StochasticResult", "check_stochastic_paths",
           "write_stochastic"]

FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


@dataclass
class StochasticResult:
    """k_eff of N random conductivity fields (:func:`~._stochastic.stochastic_k_eff`).

    Attributes
    ----------
    samples : dict of str to (N,) ndarray
        k_eff of each sample, per axis name.
    log_k_moments : (N, 2) ndarray
        Per sample, the volume-weighted mean and variance of its log k over the random
        materials (``exp`` of the mean is the sample's geometric-mean conductivity).
    at_mean : dict of str to float
        k_eff with every intensity at its mean (the deterministic reference).
    materials : dict of int to dict
        Per random material: ``name``, ``intensity_mean``, ``intensity_std``,
        ``log_k_mean``, ``log_k_std``.
    property_map : str
    correlation : tuple of float
        Correlation length per axis (array order).
    seed, order, n_cells, workers : int
    seconds : dict of str to float
    scheduler : str or None
    """

    samples: dict[str, np.ndarray]
    log_k_moments: np.ndarray
    at_mean: dict[str, float]
    materials: dict[int, dict]
    property_map: str
    correlation: tuple[float, ...]
    seed: int
    order: int
    n_cells: int
    seconds: dict[str, float] = field(default_factory=dict)
    workers: int = 1
    scheduler: str | None = None

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(next(iter(self.samples.values())))

    def statistics(self, axis: str) -> dict[str, float]:
        """``mean``, ``std``, ``low``, ``high`` (95 % of the samples), ``sem`` along `axis`.

        Parameters
        ----------
        axis : {"x", "y", "z"}

        Returns
        -------
        dict of str to float
        """
        v = self.samples[axis]
        std = float(v.std(ddof=1))
        low, high = np.percentile(v, [2.5, 97.5])
        return {"mean": float(v.mean()), "std": std, "low": float(low), "high": float(high),
                "sem": float(std / np.sqrt(len(v)))}

    def summary(self) -> dict:
        """A JSON-ready account: statistics per axis, the materials and the settings."""
        return {"samples": self.n, "seed": self.seed, "property_map": self.property_map,
                "correlation": list(self.correlation), "order": self.order,
                "elements": self.n_cells, "workers": self.workers,
                "k_eff": {a: self.statistics(a) for a in self.samples},
                "k_eff_at_mean": dict(self.at_mean),
                "materials": {str(k): dict(v) for k, v in self.materials.items()}}

    def describe(self) -> str:
        """Lines for the terminal."""
        lines = [f"stochastic k_eff: {self.n} samples (seed {self.seed}), map "
                 f"{self.property_map}, correlation length "
                 f"{', '.join(f'{c:g}' for c in self.correlation)}, P{self.order} on "
                 f"{self.n_cells} elements"]
        for label, m in sorted(self.materials.items()):
            lines.append(f"  material {label}{' (' + m['name'] + ')' if m['name'] else ''}: "
                         f"intensity {m['intensity_mean']:.6g} +- {m['intensity_std']:.3g}"
                         f" -> log k {m['log_k_mean']:.4g} +- {m['log_k_std']:.3g} "
                         f"(geometric mean k {np.exp(m['log_k_mean']):.6g})")
        for a in self.samples:
            s = self.statistics(a)
            lines.append(f"  k_eff {a} = {s['mean']:.6g} +- {s['sem']:.2g} (Monte-Carlo "
                         f"standard error); std {s['std']:.4g}; 95 % of samples in "
                         f"[{s['low']:.6g}, {s['high']:.6g}]; at the mean intensities "
                         f"{self.at_mean[a]:.6g}")
        return "\n".join(lines)

    def csv_text(self) -> str:
        """The sample table: ``sample,k_eff_x,...`` one row per sample."""
        axes = list(self.samples)
        buf = _io.StringIO()
        buf.write(",".join(["sample"] + [f"k_eff_{a}" for a in axes]) + "\n")
        for i in range(self.n):
            buf.write(",".join([str(i)] + [repr(float(self.samples[a][i])) for a in axes])
                      + "\n")
        return buf.getvalue()

    def figure(self, figure=None):
        """The histogram of k_eff per axis, mean and 95 % interval marked.

        Parameters
        ----------
        figure : matplotlib.figure.Figure, optional
            Drawn into (cleared first); default a new one.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6, 3.6), layout="constrained") if figure is None else figure
        fig.clear()
        ax = fig.add_subplot()
        colours = ("tab:blue", "tab:orange", "tab:green")
        every = np.concatenate(list(self.samples.values()))
        bins = np.histogram_bin_edges(every, bins=max(5, min(40, int(np.sqrt(self.n)) + 1))
                                      * len(self.samples))   # one set of edges for all
        for colour, a in zip(colours, self.samples):
            s = self.statistics(a)
            ax.hist(self.samples[a], bins=bins, alpha=0.55, color=colour,
                    label=f"{a}: mean {s['mean']:.4g} +- {s['sem']:.2g} (s.e.)")
            ax.axvline(s["mean"], color=colour, lw=1.5)
            for edge in (s["low"], s["high"]):
                ax.axvline(edge, color=colour, lw=1, ls="--")
        ax.set_xlabel("k_eff")
        ax.set_ylabel("samples")
        ax.set_title(f"{self.n} samples, {self.property_map}; dashed: 95 % of samples",
                     fontsize=9)
        ax.legend(fontsize=8)
        return fig


def check_stochastic_paths(table=None, histogram=None, *, force: bool = False) -> list[Path]:
    """Check the sample table (.csv) and histogram (.png/.pdf/.svg) paths before work.

    Parameters
    ----------
    table, histogram : str or Path, optional
    force : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The paths given, table first.
    """
    out = []
    if table is not None:
        if Path(table).suffix.lower() != ".csv":
            raise ValueError(f"the sample table is written as CSV: give a .csv path, not "
                             f"{Path(table).name}.")
        out.append(check_writable(table, force=force))
    if histogram is not None:
        if Path(histogram).suffix.lower() not in FIGURE_SUFFIXES:
            raise ValueError(f"the histogram is a figure: give a path ending in "
                             f"{', '.join(FIGURE_SUFFIXES)}, not {Path(histogram).name}.")
        out.append(check_writable(histogram, force=force))
    if len(out) == 2 and out[0].resolve() == out[1].resolve():
        raise ValueError("the sample table and the histogram need two different paths.")
    return out


def write_stochastic(result: StochasticResult, *, table=None, histogram=None,
                     force: bool = False) -> list[Path]:
    """Write the sample table and/or the histogram, all or nothing.

    Parameters
    ----------
    result : StochasticResult
    table : str or Path, optional
        The ``.csv`` of the samples.
    histogram : str or Path, optional
        The figure (``.png``, ``.pdf`` or ``.svg``).
    force : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The files written.
    """
    paths = check_stochastic_paths(table, histogram, force=force)
    if not paths:
        return []
    with atomic_write(paths, force=force) as temps:
        k = 0
        if table is not None:
            temps[k].write_text(result.csv_text())
            k += 1
        if histogram is not None:
            result.figure().savefig(temps[k], dpi=120)
    return paths
