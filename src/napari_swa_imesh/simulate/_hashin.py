"""Hashin-Shtrikman bounds for two isotropic phases, and their trace form.

For two isotropic phases ``k1 < k2`` with volume fractions ``f1 + f2 = 1`` in ``d``
dimensions, the Hashin-Shtrikman interval

    lower = k1 + f2 / (1 / (k2 - k1) + f1 / (d k1)),
    upper = k2 + f1 / (1 / (k1 - k2) + f2 / (d k2))

bounds the effective conductivity of every *statistically isotropic* microstructure with
those fractions. A finite image is rarely isotropic (a laminate along its layers reaches
the arithmetic mean, above ``upper``), so the interval is no test of a single axis. What
holds for every microstructure, isotropic or not, is its trace form (Lurie-Cherkaev and
Murat-Tartar; Milton, *The Theory of Composites*, section 23): for the effective tensor
``K`` of the periodic cell,

    tr (K - k1 I)^-1 <= d / (f2 (k2 - k1)) + f1 / (f2 k1),
    tr (k2 I - K)^-1 <= d / (f1 (k2 - k1)) - f2 / (f1 k2),

with equality for an isotropic ``K`` at the scalar bounds. The periodic protocol gives
``K``; a conforming discretisation overestimates it (in the order of positive definite
matrices: its fluctuations are a subspace of the exact ones), and the left side of the
first inequality decreases as ``K`` grows, so the lower trace bound holds for the discrete
tensor too and a violation is a bug. The upper one can be crossed by discretisation error
when the microstructure is near optimal (coated inclusions), so it is reported, not
enforced.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["HashinShtrikman", "hashin_shtrikman", "two_isotropic_phases"]

TRACE_SLACK = 1e-6  # relative; the solver's residual is 1e-10
SOLVE_ERROR = 1e-8  # relative error of K, times k2 / (k2 - k1) for that of K - k1
NEAR_EQUAL = 1e-6   # phases closer than this (relative) are one material to the bounds


def hashin_shtrikman(k_low: float, k_high: float, f_high: float, dim: int
                     ) -> tuple[float, float]:
    """Hashin-Shtrikman bounds on the isotropic conductivity of a two-phase mixture.

    Parameters
    ----------
    k_low, k_high : float
        Conductivities of the two phases, ``0 < k_low <= k_high``.
    f_high : float
        Volume fraction of the ``k_high`` phase, in ``[0, 1]``.
    dim : {2, 3}

    Returns
    -------
    (lower, upper) : (float, float)

    Examples
    --------
    >>> lo, hi = hashin_shtrikman(1.0, 10.0, 0.5, 2)
    >>> round(lo, 4), round(hi, 4)
    (2.3846, 4.1935)
    """
    k1, k2, f2 = float(k_low), float(k_high), float(f_high)
    if not (0 < k1 <= k2 and np.isfinite(k2) and 0 <= f2 <= 1 and dim in (2, 3)):
        raise ValueError("hashin_shtrikman needs 0 < k_low <= k_high (finite), a fraction "
                         f"in [0, 1] and dim 2 or 3; got {k_low}, {k_high}, {f_high}, {dim}.")
    f1 = 1.0 - f2
    if k1 == k2 or f2 in (0.0, 1.0):
        mean = f1 * k1 + f2 * k2
        return mean, mean
    lower = k1 + f2 / (1.0 / (k2 - k1) + f1 / (dim * k1))
    upper = k2 + f1 / (1.0 / (k1 - k2) + f2 / (dim * k2))
    return lower, upper


@dataclass(frozen=True)
class HashinShtrikman:
    """Hashin-Shtrikman bounds of a two-phase result (see the module notes).

    Attributes
    ----------
    k_low, k_high : float
        The phases' conductivities.
    f_high : float
        Volume fraction of the more conducting phase.
    lower, upper : float
        The scalar bounds (for statistically isotropic microstructures).
    trace_lower, trace_upper : (float, float) or None
        With a full effective tensor (periodic protocol, every axis) and phases that
        differ by more than round-off: ``(value, bound)`` of each trace inequality,
        ``value <= bound`` when it holds.
    slack : float
        Relative tolerance of the comparison (grows as the phases approach each other).
    """

    k_low: float
    k_high: float
    f_high: float
    lower: float
    upper: float
    trace_lower: tuple[float, float] | None = None
    trace_upper: tuple[float, float] | None = None
    slack: float = 0.0

    @property
    def trace_holds(self) -> tuple[bool, bool] | None:
        """Whether the lower and upper trace inequalities hold (None without a tensor)."""
        if self.trace_lower is None or self.trace_upper is None:
            return None
        slack = max(self.slack, TRACE_SLACK)
        return (_holds(*self.trace_lower, slack), _holds(*self.trace_upper, slack))

    def to_dict(self) -> dict:
        """Plain JSON-able values."""
        out: dict[str, object] = {"k_low": self.k_low, "k_high": self.k_high,
                                  "f_high": self.f_high, "lower": self.lower,
                                  "upper": self.upper}
        holds = self.trace_holds
        if self.trace_lower is not None and self.trace_upper is not None and holds:
            out["trace_lower"] = {"value": self.trace_lower[0], "bound": self.trace_lower[1],
                                  "holds": holds[0]}
            out["trace_upper"] = {"value": self.trace_upper[0], "bound": self.trace_upper[1],
                                  "holds": holds[1]}
        return out

    @classmethod
    def of(cls, k_low: float, k_high: float, f_high: float, dim: int,
           tensor: np.ndarray | None = None) -> HashinShtrikman:
        """The bounds, with the trace inequalities evaluated for `tensor` if given.

        Raises ValueError when the lower trace inequality fails: no conforming solution
        can do that (module notes).
        """
        lower, upper = hashin_shtrikman(k_low, k_high, f_high, dim)
        trace_lower = trace_upper = None
        # with nearly equal phases K - k1 is round-off: no inequality can be read there
        if tensor is not None and k_high - k_low > NEAR_EQUAL * k_low and 0 < f_high < 1:
            k = 0.5 * (np.asarray(tensor, dtype=float) + np.asarray(tensor, dtype=float).T)
            eig = np.linalg.eigvalsh(k)
            f1, f2 = 1.0 - f_high, f_high
            with np.errstate(divide="ignore"):
                lo_value = float(np.sum(1.0 / (eig - k_low))) if np.all(eig > k_low) else np.inf
                hi_value = float(np.sum(1.0 / (k_high - eig))) if np.all(eig < k_high) else np.inf
            trace_lower = (lo_value, dim / (f2 * (k_high - k_low)) + f1 / (f2 * k_low))
            trace_upper = (hi_value, dim / (f1 * (k_high - k_low)) - f2 / (f1 * k_high))
            # the solve's relative error in K - k1 grows as k2 / (k2 - k1)
            slack = TRACE_SLACK + SOLVE_ERROR * k_high / (k_high - k_low)
            if not _holds(*trace_lower, slack):
                raise ValueError(
                    f"the effective tensor's eigenvalues {', '.join(f'{e:.6g}' for e in eig)} "
                    "break the Hashin-Shtrikman lower trace bound (tr (K - k1 I)^-1 = "
                    f"{lo_value:.6g} > {trace_lower[1]:.6g}): the mesh or the solve is wrong; "
                    "please report this with the input.")
            return cls(float(k_low), float(k_high), float(f_high), lower, upper,
                       trace_lower, trace_upper, slack)
        return cls(float(k_low), float(k_high), float(f_high), lower, upper)


def _holds(value: float, bound: float, slack: float = TRACE_SLACK) -> bool:
    return bool(value <= bound * (1 + slack))


def two_isotropic_phases(tensors: np.ndarray, fractions: np.ndarray
                         ) -> tuple[float, float, float] | None:
    """``(k_low, k_high, f_high)`` when the box holds exactly two isotropic materials.

    Parameters
    ----------
    tensors : (n, d, d) ndarray
        Conductivity per meshed material.
    fractions : (n,) ndarray
        Their volume fractions of the box (an excluded material leaves ``sum < 1``).

    Returns
    -------
    tuple or None
        None for one or three materials, an anisotropic one, or excluded (void) volume.
    """
    tensors = np.asarray(tensors, dtype=float)
    fractions = np.asarray(fractions, dtype=float)
    if len(tensors) != 2 or fractions.sum() < 1 - 1e-9:
        return None
    d = tensors.shape[1]
    scalars = tensors[:, 0, 0]
    if not np.allclose(tensors, scalars[:, None, None] * np.eye(d), rtol=1e-12, atol=0):
        return None
    low, high = (0, 1) if scalars[0] <= scalars[1] else (1, 0)
    f_high = float(fractions[high] / fractions.sum())
    return float(scalars[low]), float(scalars[high]), f_high
