"""Stationary Gaussian random fields on a voxel grid, sampled exactly by circulant embedding.

The covariance is the squared exponential ``C(r) = exp(-sum_i (r_i / l_i)^2)`` with unit
variance and a correlation length ``l_i`` per axis (the RES tile side for the stochastic
step). The grid of ``n_i`` points is embedded in a periodic grid of ``P_i >= 2 n_i`` points
(larger where ``l_i`` needs it), on which the covariance matrix is circulant and diagonal in
the Fourier basis: with ``lambda = FFT(c)`` non-negative, ``Z = IFFT(sqrt(lambda) FFT(W))``
of white noise ``W`` has exactly the covariance ``C`` on the first ``n_i`` points (Dietrich
and Newsam 1997). The squared exponential's eigenvalues can dip below zero by rounding; the
embedding is enlarged until the negative part is below :data:`NEGATIVE_SHARE` of the
variance, and refused beyond :data:`MAX_EMBEDDING` points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft as _fft

__all__ = ["GaussianField", "MAX_EMBEDDING", "NEGATIVE_SHARE", "gaussian_field"]

NEGATIVE_SHARE = 1e-8          # of the variance, dropped with the negative eigenvalues
MAX_EMBEDDING = 1 << 25        # periodic grid points (a few hundred MB of complex128)


@dataclass(frozen=True)
class GaussianField:
    """A sampler of a unit-variance Gaussian field on a grid (:func:`gaussian_field`).

    Attributes
    ----------
    shape : tuple of int
        Grid points per axis (the field's shape).
    spacing : (d,) ndarray of float
        Distance between grid points per axis.
    correlation : (d,) ndarray of float
        Correlation length per axis.
    periodic : tuple of int
        Points per axis of the periodic (embedding) grid.
    root : ndarray of float
        Square roots of the circulant embedding's eigenvalues, on the half spectrum of
        the periodic grid (``rfftn``'s layout; the eigenvalues are even, so the
        synthesis is real).
    """

    shape: tuple[int, ...]
    spacing: np.ndarray
    correlation: np.ndarray
    periodic: tuple[int, ...]
    root: np.ndarray

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """One realisation, ``shape`` float64 values of mean 0 and variance 1.

        Parameters
        ----------
        rng : numpy.random.Generator
            The source of the white noise (seed it for a reproducible field).

        Returns
        -------
        ndarray of float64
        """
        noise = rng.standard_normal(self.periodic)
        z = _fft.irfftn(self.root * _fft.rfftn(noise, workers=1), s=self.periodic,
                        workers=1)
        return np.ascontiguousarray(z[tuple(slice(0, n) for n in self.shape)])


def _eigenvalues(periodic: tuple[int, ...], spacing: np.ndarray,
                 correlation: np.ndarray) -> np.ndarray:
    exponent = 0.0
    for axis, (p, h, ell) in enumerate(zip(periodic, spacing, correlation)):
        j = np.arange(p)
        lag = np.minimum(j, p - j) * h / ell                    # (p,) periodic distance
        shape = [1] * len(periodic)
        shape[axis] = p
        exponent = exponent - (lag ** 2).reshape(shape)
    return _fft.rfftn(np.exp(exponent), workers=1).real


def gaussian_field(shape, spacing, correlation) -> GaussianField:
    """The circulant-embedding sampler of a squared-exponential Gaussian field.

    Parameters
    ----------
    shape : sequence of int
        Grid points per axis.
    spacing : float or sequence of float
        Distance between grid points per axis (positive).
    correlation : float or sequence of float
        Correlation length per axis (positive): ``C(r) = exp(-sum (r_i / l_i)^2)``.

    Returns
    -------
    GaussianField

    Raises
    ------
    ValueError
        A non-positive size, spacing or length, or an embedding beyond
        :data:`MAX_EMBEDDING` points.

    Examples
    --------
    >>> f = gaussian_field((8, 8), 1.0, 2.0)
    >>> f.sample(np.random.default_rng(0)).shape
    (8, 8)
    """
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (d,)).copy()
    correlation = np.broadcast_to(np.asarray(correlation, dtype=np.float64), (d,)).copy()
    if d == 0 or min(shape) < 1:
        raise ValueError(f"the grid needs at least one point per axis, not {shape}.")
    for what, v in (("spacing", spacing), ("correlation length", correlation)):
        if not (np.isfinite(v).all() and (v > 0).all()):
            raise ValueError(f"the {what} must be positive per axis, not {v.tolist()}.")
    # at least twice the grid (exact on every lag) and a few lengths beyond it
    periodic = [_fft.next_fast_len(max(2 * n, n + int(np.ceil(3 * ell / h))))
                for n, h, ell in zip(shape, spacing, correlation)]
    while True:
        if int(np.prod(periodic, dtype=np.int64)) > MAX_EMBEDDING:
            raise ValueError(
                f"the random field's embedding would take {np.prod(periodic):,} points, "
                f"above {MAX_EMBEDDING:,}: the correlation length is too long or the grid "
                "too fine for the box; give a shorter correlation length or a coarser "
                "grid.")
        lam = _eigenvalues(tuple(periodic), spacing, correlation)   # half spectrum
        if -lam[lam < 0].sum() <= NEGATIVE_SHARE * np.abs(lam).sum():
            break
        periodic = [_fft.next_fast_len(2 * p) for p in periodic]
    lam = np.clip(lam, 0.0, None)
    # the variance is the mean eigenvalue over the full spectrum: the half spectrum's
    # columns other than the zero (and an even length's Nyquist) one count twice
    last = periodic[-1]
    weight = np.full(lam.shape[-1], 2.0)
    weight[0] = 1.0
    if last % 2 == 0:
        weight[-1] = 1.0
    variance = float((lam * weight).sum()) / float(np.prod(periodic, dtype=np.float64))
    root = np.sqrt(lam / variance)
    return GaussianField(shape, spacing, correlation, tuple(periodic), root)
