"""Per-pixel SWA statistics in centred sliding windows, for the recommended method.

Tiles quantise every boundary to 2^j px; here the statistics of scale j are taken in a
centred window of ``2^j + 1`` px per axis around every pixel (separable box filters, O(N)
per scale), so labels are full resolution and never shifted. Scale 0 is the pixel's own
value. Level j sees every statistic of scales 0..j: the window mean and log standard
deviation (the first two SWA moments) and the log energy of the Haar details of every finer
level k < j in the window (summed over axes, so rotation matters less). Skewness and
kurtosis were measured to *hurt* on textures (window estimates too noisy), so they are
left out.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

__all__ = ["multiscale_features", "multiscale_feature_names", "feature_levels", "window",
           "haar_energy", "LOG_FLOOR"]

LOG_FLOOR = 1e-12       # floor under variances/energies before the log (flat regions)


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

        def part(a, start, stop):
            return a[(slice(None),) * axis + (slice(start, stop),)]

        # block[m] = mean of the s pixels from original index m - s, m = 0 .. n + s
        block = (part(c, s, n + 2 * s + 1) - part(c, 0, n + s + 1)) / s
        d = (part(block, s, n + s + 1) - part(block, 0, n + 1)).astype(np.float32)
        d *= d                                   # (n + 1) squared details, at i - 1/2
        energy += 0.5 * (part(d, 0, n) + part(d, 1, n + 1))
    return energy


def multiscale_feature_names(max_scale: int) -> list[str]:
    """Names of the features of levels 0..max_scale, in stack order.

    Examples
    --------
    >>> multiscale_feature_names(2)
    ['value', 'mean@1', 'logstd@1', 'haar0@1', 'mean@2', 'logstd@2', 'haar0@2', 'haar1@2']
    """
    names = ["value"]
    for j in range(1, max_scale + 1):
        names += [f"mean@{j}", f"logstd@{j}"] + [f"haar{k}@{j}" for k in range(j)]
    return names


def feature_levels(names: list[str]) -> np.ndarray:
    """The level of every feature name (``value`` is level 0)."""
    return np.array([0 if n == "value" else int(n.split("@")[1]) for n in names])


def multiscale_features(image, max_scale: int) -> tuple[np.ndarray, list[str]]:
    """Per-pixel SWA statistics in centred windows of 2^j + 1 px, for j = 0..max_scale.

    Parameters
    ----------
    image : (M, N[, P]) array_like
        Grey-level image.
    max_scale : int
        Largest scale (window of ``2**max_scale + 1`` px per axis).

    Returns
    -------
    features : (M, N[, P], F) ndarray of float32
        Channel-last stack; F = 1 + sum_j (2 + j). Scale 0 is the pixel value; scale j
        adds the window mean, the log standard deviation and the log mean energy of the
        Haar details of levels k < j (all O(N) box filters).
    names : list of str
        ``value``, ``mean@j``, ``logstd@j``, ``haar{k}@j``.
    """
    x = np.asarray(image, dtype=np.float32)
    names = multiscale_feature_names(max_scale)
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
            out[..., c] = 0.5 * np.log(np.maximum(ndi.uniform_filter(energies[k], w, mode="reflect"), LOG_FLOOR))
            c += 1
    return out, names
