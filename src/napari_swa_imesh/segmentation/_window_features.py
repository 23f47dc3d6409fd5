"""Per-pixel SWA statistics in centred sliding windows, for the recommended method.

Tiles quantise every boundary to 2^j px; here the statistics of scale j are taken in a
centred window of ``2^j + 1`` px per axis around every pixel (separable box filters, O(N)
per scale), so labels are full resolution and never shifted. Scale 0 is the pixel's own
value. Level j sees every statistic of scales 0..j: the window mean and log standard
deviation (the first two SWA moments) and the log energy of the Haar details of every finer
level k < j in the window (summed over axes, so rotation matters less). Skewness and
kurtosis were measured to *hurt* on textures (window estimates too noisy), so they are
left out.

From level 3 on, level j also sees how *oriented* the texture is, without its direction:
the window mean of the squared coherence of the local structure tensor (gradients of
level k, tensor averaged over a window of level m = k + 1 or k + 2, m <= j - 2, so the
window holds many tensor windows). Coherence is 0 for isotropic detail and 1 for detail
all in one direction (stripes, blades of grass); it is a function of the tensor's
eigenvalues, so turning, flipping or transposing the image does not change it (the signed
per-axis energy ratio that was measured instead makes a texture turned by 90 degrees
another material). It raised the 5-texture Voronoi mosaic from 0.763 to 0.803 mean Dice.
Levels 0..2, which the MR-like tissues use, are unchanged.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

__all__ = ["multiscale_features", "multiscale_feature_names", "feature_levels", "window",
           "haar_energy", "coherence_pairs", "squared_coherence", "LOG_FLOOR"]

LOG_FLOOR = 1e-12       # floor under variances/energies before the log (flat regions)
COHERENCE_SPANS = (1, 2)    # tensor window level m = k + span over the gradient level k
COHERENCE_GAP = 2           # ... and m <= j - 2: a level-j window averages >= 4x4 of them


def window(level: int) -> int:
    """Window side of `level`: 2^level + 1 px (centred on the pixel), 1 px at level 0."""
    return (1 << level) + 1 if level else 1


def haar_energy(x: np.ndarray, level: int) -> np.ndarray:
    """Squared Haar detail of `level` summed over axes, centred on every pixel.

    The detail at pixel i along an axis is the mean of the s = 2^level pixels from i minus
    the mean of the s pixels before i (centred on i - 1/2); averaging its square at i and
    i + 1 centres it on i, so the feature does not shift boundaries. The image is mirrored
    by s pixels at both ends (as the box filters do), so flipping the image flips the
    feature exactly.
    """
    s = 1 << level
    energy = np.zeros(x.shape, np.float32)
    for axis in range(x.ndim):
        n = x.shape[axis]
        pad = [(0, 0)] * x.ndim
        pad[axis] = (s, s)
        # running sums in float64: block means of large-offset data stay exact enough
        c = np.cumsum(np.pad(x, pad, mode="symmetric"), axis=axis, dtype=np.float64)
        c = np.concatenate([np.zeros_like(np.take(c, [0], axis=axis)), c], axis=axis)

        def part(a, start, stop, axis=axis):
            return a[(slice(None),) * axis + (slice(start, stop),)]

        # block[m] = mean of the s pixels from original index m - s, m = 0 .. n + s
        block = (part(c, s, n + 2 * s + 1) - part(c, 0, n + s + 1)) / s
        d = (part(block, s, n + s + 1) - part(block, 0, n + 1)).astype(np.float32)
        d *= d                                   # (n + 1) squared details, at i - 1/2
        energy += 0.5 * (part(d, 0, n) + part(d, 1, n + 1))
    return energy


def coherence_pairs(level: int) -> list[tuple[int, int]]:
    """(gradient level k, tensor window level m) of the coherence features of `level`.

    Examples
    --------
    >>> coherence_pairs(2), coherence_pairs(3), coherence_pairs(4)
    ([], [(0, 1)], [(0, 1), (0, 2), (1, 2)])
    """
    return [(k, k + s) for k in range(level) for s in COHERENCE_SPANS
            if k + s <= level - COHERENCE_GAP]


def _gradients(x: np.ndarray, level: int) -> list[np.ndarray]:
    """Central differences, one per axis, of `x` box-smoothed over window(level), taken
    2^(level-1) px either side (1 px at level 0), so they are centred on the pixel."""
    smooth = x if level == 0 else ndi.uniform_filter(x, window(level), mode="reflect")
    h = max(1, (1 << level) >> 1)
    weights = np.zeros(2 * h + 1, np.float32)
    weights[0], weights[-1] = -0.5, 0.5
    return [ndi.correlate1d(smooth, weights, axis=a, mode="reflect") for a in range(x.ndim)]


def squared_coherence(x: np.ndarray, k: int, m: int) -> np.ndarray:
    """Squared coherence of the structure tensor of level-k gradients averaged over
    window(m), per pixel, in [0, 1].

    From the tensor's invariants (no eigen-decomposition, same code in 2-D and 3-D):
    ``(d tr(T^2) / tr(T)^2 - 1) / (d - 1)``, which is ``((l1 - l2) / (l1 + l2))^2`` in 2-D
    and 0 where the gradients have no preferred direction (or none at all).

    Examples
    --------
    >>> stripes = np.tile(np.sin(np.arange(16) / 2.0), (16, 1)).astype(np.float32)
    >>> float(squared_coherence(stripes, 0, 2)[8, 8]) > 0.99
    True
    """
    g = _gradients(x, k)
    w = window(m)
    trace = np.zeros(x.shape, np.float32)
    trace2 = np.zeros(x.shape, np.float32)
    for a in range(x.ndim):
        for b in range(a, x.ndim):
            t = ndi.uniform_filter(g[a] * g[b], w, mode="reflect")
            if a == b:
                trace += t
            t *= t
            trace2 += t if a == b else 2 * t
    del g
    d = x.ndim
    ratio = trace2 / np.maximum(trace * trace, LOG_FLOOR)
    return np.clip((d * ratio - 1) / (d - 1), 0, 1)


def multiscale_feature_names(max_scale: int, coherence: bool = True) -> list[str]:
    """Names of the features of levels 0..max_scale, in stack order.

    Parameters
    ----------
    max_scale : int
        The coarsest level.
    coherence : bool
        Include the structure-tensor coherence features (from level 3 on).

    Returns
    -------
    list of str
        One name per feature channel of :func:`multiscale_features`.

    Examples
    --------
    >>> multiscale_feature_names(2)
    ['value', 'mean@1', 'logstd@1', 'haar0@1', 'mean@2', 'logstd@2', 'haar0@2', 'haar1@2']
    >>> multiscale_feature_names(3)[8:]
    ['mean@3', 'logstd@3', 'haar0@3', 'haar1@3', 'haar2@3', 'coh0w1@3']
    """
    names = ["value"]
    for j in range(1, max_scale + 1):
        names += [f"mean@{j}", f"logstd@{j}"] + [f"haar{k}@{j}" for k in range(j)]
        names += [f"coh{k}w{m}@{j}" for k, m in coherence_pairs(j) if coherence]
    return names


def feature_levels(names: list[str]) -> np.ndarray:
    """The level of every feature name (``value`` is level 0)."""
    return np.array([0 if n == "value" else int(n.split("@")[1]) for n in names])


def multiscale_features(image, max_scale: int, coherence: bool = True
                        ) -> tuple[np.ndarray, list[str]]:
    """Per-pixel SWA statistics in centred windows of 2^j + 1 px, for j = 0..max_scale.

    Parameters
    ----------
    image : (M, N[, P]) array_like
        Grey-level image.
    max_scale : int
        Largest scale (window of ``2**max_scale + 1`` px per axis).
    coherence : bool
        Include the coherence features (False: the stack of models saved before them).

    Returns
    -------
    features : (M, N[, P], F) ndarray of float32
        Channel-last stack. Scale 0 is the pixel value; scale j adds the window mean, the
        log standard deviation, the log mean energy of the Haar details of levels k < j
        and, from j = 3, the window mean of the squared coherence of every pair of
        :func:`coherence_pairs` (all O(N) box filters).
    names : list of str
        ``value``, ``mean@j``, ``logstd@j``, ``haar{k}@j``, ``coh{k}w{m}@j``.
    """
    x = np.asarray(image, dtype=np.float32)
    names = multiscale_feature_names(max_scale, coherence)
    out = np.empty(x.shape + (len(names),), np.float32)
    out[..., 0] = x
    energies = [haar_energy(x, k) for k in range(max_scale)]
    c = 1
    for j in range(1, max_scale + 1):
        w = window(j)
        # reflect = numpy's "symmetric" (edge pixel repeated), as haar_energy pads
        mean = ndi.uniform_filter(x, w, mode="reflect")
        var = ndi.uniform_filter(x * x, w, mode="reflect") - mean * mean
        out[..., c] = mean
        out[..., c + 1] = 0.5 * np.log(np.maximum(var, LOG_FLOOR))
        c += 2
        for k in range(j):
            out[..., c] = 0.5 * np.log(np.maximum(
                ndi.uniform_filter(energies[k], w, mode="reflect"), LOG_FLOOR))
            c += 1
        c += len(coherence_pairs(j)) if coherence else 0
    del energies
    # one coherence map at a time, averaged into every level that uses it (bounds memory)
    column = {n: i for i, n in enumerate(names)}
    for k, m in coherence_pairs(max_scale) if coherence else []:
        coh = squared_coherence(x, k, m)
        for j in range(m + COHERENCE_GAP, max_scale + 1):
            out[..., column[f"coh{k}w{m}@{j}"]] = ndi.uniform_filter(coh, window(j), mode="reflect")
    return out, names
