"""Smooth multiplicative bias field (MR-like data; EM-style, after Van Leemput et al. 1999).

The field is the locally weighted least-squares ratio of the image to its class means,
``b = G*(I mu) / G*(mu^2)``, with G a wide Gaussian, computed on a coarse grid (the field is
smooth by assumption, so the grid costs nothing in accuracy) and interpolated back.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ._tiles import block_mean

__all__ = ["estimate_bias_field", "upsample_linear", "GRID_CELLS"]

GRID_CELLS = 32         # coarse grid: about this many cells along the shortest side
_TINY = 1e-12           # relative floor under G*(mu^2) (regions of class mean 0)
_NONE = 1e-30           # floor of that floor when every class mean is 0


def upsample_linear(small: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Linear interpolation of a coarse grid onto `shape`, cell centre to cell centre
    (``grid_mode``), edge values held beyond the outer centres; float32 in, float32 out."""
    zoom = [n / m for n, m in zip(shape, small.shape)]
    return ndi.zoom(small, zoom, order=1, mode="nearest", grid_mode=True, prefilter=False)


def estimate_bias_field(image, labels, class_means: dict[int, float], *,
                        smoothness: float = 0.15) -> np.ndarray:
    """Smooth multiplicative bias b with ``image ~ b * mean(label)``.

    Locally weighted least squares: ``b = G*(I mu) / G*(mu^2)`` where mu is the class mean
    of each pixel's label and G a Gaussian of ``smoothness`` times the smallest image side,
    computed on a grid about :data:`GRID_CELLS` cells across (the field is smooth by
    assumption) and interpolated back.

    Parameters
    ----------
    image : (M, N[, P]) ndarray
    labels : (M, N[, P]) ndarray of int
    class_means : dict of int to float
        Mean intensity of every label.
    smoothness : float
        Gaussian sigma as a fraction of the shortest side (the field varies slowly across
        the image).

    Returns
    -------
    (M, N[, P]) ndarray of float32
        The field (1 where the image matches the class means).
    """
    keys = np.array(sorted(class_means))                 # labels may be any 63-bit value
    values = np.array([class_means[k] for k in keys], np.float32)
    mu = values[np.minimum(np.searchsorted(keys, labels), keys.size - 1)]
    factor = max(1, min(image.shape) // GRID_CELLS)
    num = block_mean(np.asarray(image, np.float32) * mu, factor)
    den = block_mean(mu * mu, factor)
    sigma = smoothness * min(num.shape)
    num = ndi.gaussian_filter(num, sigma, mode="nearest")
    den = ndi.gaussian_filter(den, sigma, mode="nearest")
    field = num / np.maximum(den, _TINY * max(float(den.max()), _NONE))
    field = np.where(field > 0, field, 1.0).astype(np.float32)
    return upsample_linear(field, image.shape)          # float32 in, float32 out
