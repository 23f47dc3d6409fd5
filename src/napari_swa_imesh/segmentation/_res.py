"""Representative elementary scale (RES): tile-moment statistics against scale (sec. 2.4.1.3).

For every material and scale j, the moments of every tile of 2^j pixels per axis that lies
wholly inside one of the material's sample boxes (tiles aligned to the box's own corner,
as the reference computes statistics on each sample) are pooled; the RES table holds their
mean, standard deviation, minimum and maximum. A material says nothing at a scale where it
has fewer than 2^d tiles.

Suggested RES (the reference leaves the pick to the user; this is our documented rule,
after the representative-volume criteria of continuum mechanics: the property stops
changing with window size and stops varying between windows). For each material, scale j
is *stable* when, with v(j) the average tile variance and m(j) the average tile mean,

* ``|v(j) - v(j-1)| <= change_tol * v(j)`` and ``|m(j) - m(j-1)| <= change_tol * sqrt(v(j))``
  (the statistics no longer drift as tiles grow), and
* ``std over tiles of the tile means <= spread_tol * sqrt(v(j))`` (a tile looks like any
  other tile of the same material: its mean is pinned down to a fraction of the
  material's within-tile spread).

A material's RES is the smallest scale from which every larger scale it can measure is
stable; the suggestion is the largest of the materials' RES, capped at the largest scale
where every material still has at least two tiles, and at the largest scale the classifier
of `method` can train at on these boxes (:func:`trainable_scale`): the recommended method
trains level j on windows of 2^j + 1 px, which must fit inside a box of every material;
the reference method with GM needs more full tiles than features per material. So
``segment`` at the suggested RES never has to lower it, and the reason names the box that
limits it. Skewness and kurtosis are
drawn but not used by the rule: their tile estimates are too noisy on small tiles to
decide anything.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import IMAGE_NDIM, as_image, check_ndim
from ._features import n_features
from ._moments import MOMENT_NAMES, moment_pyramid_unchecked
from ._samples import BoxCrops, Samples, check_box_contrast, check_contrast

__all__ = ["ResStatistics", "res_statistics", "res_statistics_unchecked", "suggest_res",
           "plot_res", "plot_res_scales", "MOMENT_NAMES", "box_tile_moments",
           "trainable_scale", "METHODS", "format_res_table"]

METHODS = ("recommended", "reference")    # the classifiers a suggestion can be capped for

# Colours of the plot's marks (matplotlib's tab10 red and green, readable on light and dark
# backgrounds); text, axes and background come from the caller or matplotlib's rcParams.
RES_COLOR = "#d62728"
USED_COLOR = "#2ca02c"
BAND_COLOR = "#9aa7b8"


@dataclass
class ResStatistics:
    """Tile-moment statistics per material and scale.

    Made by :func:`res_statistics`; its fields are the constructor's parameters.

    Parameters
    ----------
    scales, materials, names, mean, std, min, max, n_tiles, ndim, suggested_scale, \
material_res, reason, method
        The attributes below, in this order.

    Attributes
    ----------
    scales : (S,) ndarray of int
        Scales 0..max_scale.
    materials : list of int
        Material labels (rows of the arrays below).
    names : list of str
        Material names.
    mean, std, min, max : (K, S, 4) ndarray of float64
        Statistics over each material's tiles of (mean, variance, skewness, kurtosis);
        NaN where the material has fewer than 2^d tiles.
    n_tiles : (K, S) ndarray of int64
        Full tiles per material and scale.
    ndim : int
        Image dimensionality.
    suggested_scale : int or None
        The suggested RES (see the module docstring).
    material_res : dict of int to int or None
        Each material's own RES.
    reason : str
        One sentence on how the suggestion was reached.
    method : str
        The classifier the suggestion is capped for ("recommended" or "reference").
    """

    scales: np.ndarray
    materials: list[int]
    names: list[str]
    mean: np.ndarray
    std: np.ndarray
    min: np.ndarray
    max: np.ndarray
    n_tiles: np.ndarray
    ndim: int
    suggested_scale: int | None = None
    material_res: dict[int, int | None] = field(default_factory=dict)
    reason: str = ""
    method: str = "recommended"

    def to_dict(self) -> dict:
        """Plain-JSON form (what ``swa-imesh res --json`` prints)."""
        out = {"scales": self.scales.tolist(), "suggested_scale": self.suggested_scale,
               "reason": self.reason, "method": self.method, "moments": list(MOMENT_NAMES),
               "materials": []}
        for i, (m, name) in enumerate(zip(self.materials, self.names)):
            out["materials"].append({
                "label": m, "name": name, "res": self.material_res.get(m),
                "n_tiles": self.n_tiles[i].tolist(),
                **{stat: np.where(np.isfinite(getattr(self, stat)[i]),
                                  getattr(self, stat)[i], np.nan).tolist()
                   for stat in ("mean", "std", "min", "max")},
            })
        return out


def box_tile_moments(image: np.ndarray | BoxCrops, samples: Samples, label: int,
                     max_scale: int) -> list[np.ndarray]:
    """Moments of the full tiles inside a material's boxes, per scale.

    Returns a list over scales 0..max_scale of (n_tiles, 4) arrays, tiles aligned to each
    box's corner; partial tiles at a box's far edge are dropped.
    """
    d = image.ndim
    per_scale: list[list[np.ndarray]] = [[] for _ in range(max_scale + 1)]
    for box in samples.boxes_of(label):
        crop = np.asarray(image[box.slices], np.float64)        # a box: small
        top = min(max_scale, int(np.floor(np.log2(max(crop.shape)))))
        pyramid = moment_pyramid_unchecked(crop, None, top)
        for j, (moments, counts) in enumerate(pyramid):
            full = counts == (1 << (j * d))
            if full.any():
                per_scale[j].append(moments[full])
    return [np.concatenate(p) if p else np.zeros((0, 4)) for p in per_scale]


def res_statistics(image, samples: Samples, *, max_scale: int | None = None,
                   change_tol: float = 0.1, spread_tol: float = 0.5,
                   method: str = "recommended") -> ResStatistics:
    """Tile-moment statistics against scale for every material, and a suggested RES.

    Parameters
    ----------
    image : (M, N[, P, ...]) array_like
        Grey-level image.
    samples : Samples
        Materials and their sample boxes (checked against the image).
    max_scale : int, optional
        Largest scale; default the largest at which some material still has 2^d tiles.
    change_tol, spread_tol : float
        Tolerances of the RES rule (module docstring).
    method : {"recommended", "reference"}
        The classifier the suggestion must be trainable for (:func:`trainable_scale`).

    Returns
    -------
    ResStatistics
    """
    img = as_image(image, max_ndim=IMAGE_NDIM[-1], copy=False)
    samples.check(img.shape)
    check_contrast(img, samples)
    return res_statistics_unchecked(img, samples, max_scale=max_scale,
                                    change_tol=change_tol, spread_tol=spread_tol,
                                    method=method)


def res_statistics_of_boxes(image, samples: Samples, *, max_scale: int | None = None,
                            method: str = "recommended") -> ResStatistics:
    """:func:`res_statistics` reading only the sample boxes of a large image.

    The statistics are moments of tiles inside the boxes, so nothing else is read: a Zarr
    or Dask array or a memory-mapped ``.npy`` stays on disk. Equal to
    :func:`res_statistics` on the loaded image (each box is read as float64 either way).

    Parameters
    ----------
    image : (M, N[, P]) array-like with ``shape``, ``dtype`` and slicing
        Grey-level image of integers or floats.
    samples : Samples

    Raises
    ------
    ValueError
        For an image of another dimensionality or type, boxes outside it, NaN or infinity
        in a box, or boxes that all hold one value.
    """
    shape, dtype = tuple(int(n) for n in image.shape), np.dtype(image.dtype)
    check_ndim(shape)
    if dtype.kind not in "iuf":
        raise ValueError(f"the image must be an array of numbers, not {dtype}; give one "
                         "channel of a grey-level image.")
    samples.check(shape)
    crops = [np.asarray(image[b.slices], np.float64) for b in samples.boxes]
    for box, crop in zip(samples.boxes, crops):
        if not np.isfinite(crop).all():
            raise ValueError(f"a sample box of material {box.label} holds NaN or infinity; "
                             "move it onto valid pixels or fix the image.")
    check_box_contrast(crops)
    # the statistics read the boxes only: from these crops, so each is read once
    return res_statistics_unchecked(BoxCrops(crops, samples.boxes), samples,
                                    max_scale=max_scale, method=method)


def res_statistics_unchecked(img: np.ndarray | BoxCrops, samples: Samples, *,
                             max_scale: int | None = None, change_tol: float = 0.1,
                             spread_tol: float = 0.5, method: str = "recommended"
                             ) -> ResStatistics:
    """:func:`res_statistics` of a float image and samples already checked against it."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}.")
    d = img.ndim
    if max_scale is None:
        biggest = max(max(b.shape) for b in samples.boxes)
        max_scale = int(np.floor(np.log2(biggest)))
    if max_scale < 0:
        raise ValueError(f"max_scale must be >= 0; got {max_scale}.")
    labels = samples.labels
    k, s = len(labels), max_scale + 1
    stats = {name: np.full((k, s, 4), np.nan) for name in ("mean", "std", "min", "max")}
    n_tiles = np.zeros((k, s), np.int64)
    for i, label in enumerate(labels):
        for j, tiles in enumerate(box_tile_moments(img, samples, label, max_scale)):
            n_tiles[i, j] = tiles.shape[0]
            if tiles.shape[0] >= (1 << d):
                stats["mean"][i, j] = tiles.mean(axis=0)
                stats["std"][i, j] = tiles.std(axis=0)
                stats["min"][i, j] = tiles.min(axis=0)
                stats["max"][i, j] = tiles.max(axis=0)
    # trim scales where no material can say anything
    useful = np.flatnonzero((n_tiles >= (1 << d)).any(axis=0))
    last = int(useful.max()) + 1 if useful.size else 1
    res = ResStatistics(
        scales=np.arange(last), materials=list(labels),
        names=[samples.name_of(m) for m in labels],
        mean=stats["mean"][:, :last], std=stats["std"][:, :last],
        min=stats["min"][:, :last], max=stats["max"][:, :last],
        n_tiles=n_tiles[:, :last], ndim=d, method=method,
    )
    res.suggested_scale, res.material_res, res.reason = suggest_res(
        res, change_tol=change_tol, spread_tol=spread_tol, samples=samples)
    return res


def trainable_scale(samples: Samples, ndim: int, scale: int, *,
                    method: str = "recommended") -> tuple[int, str | None]:
    """The largest scale up to `scale` the classifier of `method` can train at on `samples`.

    The recommended method trains level j on windows of 2^j + 1 px, each inside one box
    (:meth:`Samples.window_limit`); the reference method with its default GM on F1 needs
    more full tiles of 2^j px than features in the boxes of every material
    (:meth:`Samples.tile_limit`), as ``segment`` requires.

    Returns
    -------
    scale : int
        `scale` itself when it trains, else the largest that does (-1: none).
    limit : str or None
        None when `scale` trains; else one sentence naming the box that limits it and
        what to do.

    Examples
    --------
    >>> s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [64, 64]},
    ...                                  {"label": 2, "start": [0, 0], "stop": [8, 40]}]})
    >>> trainable_scale(s, 2, 4)[0], trainable_scale(s, 2, 4, method="reference")[0]
    (2, 3)
    """
    if method == "recommended":
        limit = samples.window_limit(int(scale))
    else:
        limit = samples.tile_limit(int(scale), n_features("F1", ndim, int(scale)) + 1)
    return (int(scale), None) if limit is None else (int(limit[0]), limit[1])


def suggest_res(stats: ResStatistics, *, change_tol: float = 0.1, spread_tol: float = 0.5,
                samples: Samples | None = None
                ) -> tuple[int | None, dict[int, int | None], str]:
    """Apply the RES rule of the module docstring to a statistics table.

    With `samples` (the boxes the table came from), the suggestion is also capped at the
    largest scale the classifier of ``stats.method`` can train at (:func:`trainable_scale`).

    Returns
    -------
    scale : int or None
        Suggested RES, or None when no material has enough tiles at any scale above 0.
    material_res : dict of int to int or None
        Each material's own RES (None: never stable within its boxes).
    reason : str
    """
    mean_m = stats.mean[..., 0]                       # (K, S) average tile mean
    var_m = stats.mean[..., 1]                        # (K, S) average tile variance
    spread = stats.std[..., 0]                        # (K, S) std of tile means
    sd = np.sqrt(np.maximum(var_m, 0)) + 1e-12
    with np.errstate(invalid="ignore"):
        drift_v = np.abs(np.diff(var_m, axis=1)) <= change_tol * (var_m[:, 1:] + 1e-12)
        drift_m = np.abs(np.diff(mean_m, axis=1)) <= change_tol * sd[:, 1:]
        tight = spread[:, 1:] <= spread_tol * sd[:, 1:]
    valid = np.isfinite(var_m[:, 1:])
    stable = drift_v & drift_m & tight & valid        # (K, S-1) for scales 1..S-1
    material_res: dict[int, int | None] = {}
    for i, m in enumerate(stats.materials):
        js = np.flatnonzero(valid[i])
        found = None
        for j in js:                                   # smallest j stable from here on
            if stable[i, j:][valid[i, j:]].all():
                found = int(j) + 1
                break
        material_res[m] = found
    trainable = np.flatnonzero((stats.n_tiles >= 2).all(axis=0))
    if trainable.size == 0:
        return None, material_res, "no scale leaves every material two tiles to train on."
    cap = int(trainable.max())
    picks = [r for r in material_res.values() if r is not None]
    unstable = [stats.names[i] for i, m in enumerate(stats.materials) if material_res[m] is None]
    wanted = max(picks) if picks else cap
    limit = None
    if samples is not None:
        # the classifier's own limit at the scale the tiles allow (its sentence names the box)
        trained, limit = trainable_scale(samples, stats.ndim, min(wanted, cap),
                                         method=stats.method)
        if limit is not None and trained < 0:
            return None, material_res, (f"no scale trains the {stats.method} classifier: "
                                        f"{limit}.")
        cap = min(cap, trained)
    if not picks:
        reason = ("no material's statistics settle within its sample boxes; using the "
                  f"largest scale every material can train at ({cap}). Draw larger boxes "
                  "for a firmer RES.")
        if limit is not None:
            reason += f" The {stats.method} classifier limits it: {limit}."
        return cap, material_res, reason
    scale = wanted
    reason = (f"smallest scale from which every material's tile mean and variance stop "
              f"drifting (< {change_tol:g}) and tile means agree (< {spread_tol:g} of the "
              f"within-tile std): {scale}.")
    if unstable:
        reason += f" Not settled within their boxes: {', '.join(unstable)}."
    if scale > cap:
        reason += (f" Capped at {cap}, the largest scale the {stats.method} classifier can "
                   f"train at: " + (f"{limit}." if limit is not None else
                                    "larger tiles leave some material fewer than two "
                                    "training tiles."))
        scale = cap
    return int(scale), material_res, reason


def format_res_table(stats: ResStatistics) -> str:
    """The table ``swa-imesh res`` prints: the suggestion and its reason, then per material
    and scale the tiles, mean(mean), mean(var) and std(mean); a scale with fewer than 2^d
    tiles shows ``-`` and a footnote says why, never a bare NaN."""
    need = 1 << stats.ndim
    lines = [f"suggested RES: {stats.suggested_scale}  ({stats.reason})"]
    short = False
    for i, name in enumerate(stats.names):
        lines.append(f"{name} (label {stats.materials[i]}), own RES "
                     f"{stats.material_res.get(stats.materials[i])}:")
        lines.append("  scale  tiles      mean(mean)   mean(var)   std(mean)")
        for j in stats.scales:
            values = (stats.mean[i, j, 0], stats.mean[i, j, 1], stats.std[i, j, 0])
            if stats.n_tiles[i, j] < need:     # too few tiles for statistics across tiles
                short = True
                cells = f"{'-':>12} {'-':>11} {'-':>11}  (*)"
            else:
                cells = f"{values[0]:12.5g} {values[1]:11.5g} {values[2]:11.5g}"
            lines.append(f"  {j:5d} {stats.n_tiles[i, j]:6d} {cells}")
    if short:
        lines.append(f"(*) fewer than 2^d = {need} full tiles in the material's boxes at this "
                     "scale: too few to say how tiles vary, so no statistics (draw larger or "
                     "more boxes to see this scale).")
    lines.append("columns: mean(mean) and mean(var) average each tile's mean and variance; "
                 "std(mean) is how much the tile means differ. RES: representative "
                 "elementary scale, where these stop changing with the tile size 2^j px.")
    return "\n".join(lines)


def plot_res(stats: ResStatistics, *, figure=None, selected_scale: int | None = None,
             foreground=None, background=None, line_color=None, dark: bool = False):
    """Draw the reference's Figure 2.14 layout: rows are moments, columns materials.

    Each panel shows, against scale, the mean of the moment over the material's tiles
    (line), a +-1 std band, and the minimum and maximum (dotted). The suggested RES is a
    dashed vertical line; `selected_scale`, if given, a solid one.

    Parameters
    ----------
    stats : ResStatistics
    figure : matplotlib.figure.Figure, optional
        Figure to draw into (cleared first); a new one otherwise. No pyplot state is used,
        so this works inside a Qt canvas as well as on the command line.
    selected_scale : int, optional
    foreground, background, line_color : matplotlib colour, optional
        Text and axes, figure and panel background, the mean line. Default: matplotlib's
        rcParams (``text.color``, ``axes.facecolor``, the first colour of the cycle), so a
        style context or a themed canvas sets them.
    dark : bool
        Shorthand for matplotlib's ``dark_background`` colours where the three above are
        not given.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib as mpl
    from matplotlib.figure import Figure

    rc = mpl.rcParams
    fg = foreground or ("white" if dark else rc["text.color"])
    bg = background or ("black" if dark else rc["axes.facecolor"])
    line = line_color or rc["axes.prop_cycle"].by_key().get("color", ["C0"])[0]
    k = len(stats.materials)
    fig = figure if figure is not None else Figure(figsize=(2.6 * max(k, 1) + 1, 8.5))
    fig.clear()
    fig.set_facecolor(bg)
    axes = fig.subplots(4, max(k, 1), sharex=True, squeeze=False)
    x = stats.scales
    for c in range(k):
        for r, moment in enumerate(MOMENT_NAMES):
            ax = axes[r, c]
            ax.set_facecolor(bg)
            mu, sd = stats.mean[c, :, r], stats.std[c, :, r]
            ax.fill_between(x, mu - sd, mu + sd, color=BAND_COLOR, alpha=0.45, lw=0)
            ax.plot(x, mu, "-o", color=line, ms=3, lw=1.5)
            ax.plot(x, stats.min[c, :, r], ":", color=fg, lw=1)
            ax.plot(x, stats.max[c, :, r], ":", color=fg, lw=1)
            if stats.suggested_scale is not None:
                ax.axvline(stats.suggested_scale, color=RES_COLOR, ls="--", lw=1)
            if selected_scale is not None:
                ax.axvline(selected_scale, color=USED_COLOR, ls="-", lw=1.2)
            ax.tick_params(colors=fg, labelsize=7)
            for spine in ax.spines.values():
                spine.set_color(fg)
            if c == 0:
                ax.set_ylabel(moment, color=fg, fontsize=8)
            if r == 0:
                ax.set_title(stats.names[c], color=fg, fontsize=9)
            if r == 3:
                ax.set_xlabel("scale j (tile 2^j px)", color=fg, fontsize=8)
            ax.set_xticks(x)
    fig.suptitle(_res_title(stats), color=fg, fontsize=10)
    fig.tight_layout()
    return fig


def _res_title(stats: ResStatistics, scales=None) -> str:
    title = "Tile-moment statistics against scale"
    if stats.suggested_scale is not None:
        title += f" (suggested RES: {stats.suggested_scale})"
    if scales is not None:
        title += f"; scales used: {', '.join(map(str, scales))}"
    return title


def plot_res_scales(stats: ResStatistics, scales, *, figure=None, **colors):
    """The RES plot (:func:`plot_res`) with the scales a segmentation used shaded.

    The coarse scale is the solid line (``selected_scale``), the band from the finest
    refinement scale to it is shaded green, and the suggested RES stays dashed red, so the
    user sees where the classifier's scales sit on the statistics they came from.

    Parameters
    ----------
    stats : ResStatistics
    scales : sequence of int
        E.g. ``result.scales`` (coarse first).
    figure : matplotlib.figure.Figure, optional
    **colors
        ``foreground``, ``background``, ``line_color`` or ``dark``, as :func:`plot_res`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    scales = [int(j) for j in scales]
    fig = plot_res(stats, figure=figure, selected_scale=max(scales), **colors)
    for ax in fig.axes:
        ax.axvspan(min(scales) - 0.25, max(scales) + 0.25, color=USED_COLOR, alpha=0.12,
                   lw=0)
    fig.suptitle(_res_title(stats, scales), fontsize=10, color=fig._suptitle.get_color())
    return fig
