"""The certified interval of the periodic protocol in 2-D: bounds of the effective tensor.

**Upper** (the primal). For every periodic fluctuation ``w_i`` (converged or not) the
potentials ``u_i = x_i + w_i`` give ``G_ij = (1/V) u_i . A u_j`` (``A`` the stiffness
matrix), and for every unit mean gradient ``e``: ``e . K e <= (1/V) int grad(e . u) . C
grad(e . u) = e . G e``, because ``e . u`` is ``x . e`` plus a periodic function. So
``K <= G`` in the order of symmetric matrices.

**Lower** (the dual). ``e . K^-1 e = min <s . C^-1 s>`` over the periodic divergence-free
fluxes ``s`` with mean ``e``. In the plane those are ``s = J (g + grad psi)`` with
``g = J^T e`` and ``psi`` periodic (``J`` the rotation by a right angle), so
``<s . C^-1 s> = <(g + grad psi) . R (g + grad psi)>`` with ``R = J^T C^-1 J``: the
primal problem of the rotated inverse conductivity. Its periodic solves ``v_i`` give
``H_ij = (1/V) v_i . A_R v_j`` and, as above, ``e . K^-1 e <= g . H g = e . J H J^T e``
for every ``e``: ``K^-1 <= J H J^T``, so ``K >= (J H J^T)^-1``.

Per axis the interval is ``[((J H J^T)^-1)_aa, G_aa]`` (a diagonal entry of an ordered
pair of matrices is ordered): two more periodic solves, whatever the axes asked. 3-D has
no such rotation (its divergence-free fields are curls of vector fields): no interval.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ._assembly import Space, stiffness_matrix
from ._certify import relative_gaps
from ._periodic import PeriodicProblem
from ._solve import SolverInfo

__all__ = ["periodic_interval", "periodic_lower", "periodic_upper"]

_J = np.array([[0.0, 1.0], [-1.0, 0.0]])


def periodic_upper(matrix: sparse.csr_matrix, potential: np.ndarray, volume: float
                   ) -> float:
    """``G_aa = (1/V) u . A u``: the upper bound of ``K_aa`` from the potential ``u`` of
    the periodic solve along axis a."""
    return float(potential @ (matrix @ potential)) / volume


def periodic_lower(space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                   lo: np.ndarray, hi: np.ndarray, *, tol: float
                   ) -> tuple[np.ndarray, list[SolverInfo]] | None:
    """``(J H J^T)^-1`` (mesh axis order): a lower bound of the effective tensor in the
    order of symmetric matrices, from the rotated inverse conductivity's periodic solves.

    Parameters
    ----------
    space : Space
        The primal's P1 or P2 space of a periodic triangle mesh.
    tensors : (n_materials, 2, 2) ndarray
        Conductivities (invertible), mesh axis order.
    cell_material : (M,) ndarray of int
    lo, hi : (2,) ndarray
        The box.
    tol : float
        Relative residual of the two solves (the bound holds whatever it is).

    Returns
    -------
    (2, 2) ndarray and the two solves' reports, or None
        None when ``J H J^T`` is not positive definite (no finite lower bound).
    """
    inverse = np.linalg.inv(np.asarray(tensors, dtype=np.float64))
    rotated = np.einsum("ji,mjk,kl->mil", _J, inverse, _J)              # J^T C^-1 J
    matrix = stiffness_matrix(space, rotated, cell_material)
    problem = PeriodicProblem(matrix, space.doflocs, lo, hi, tol=tol)
    volume = float(np.prod(hi - lo))
    solves = [problem.solve(i) for i in range(2)]
    v = np.stack([u for _, u, _ in solves])
    h = v @ (matrix @ v.T) / volume
    h = 0.5 * (h + h.T)
    m = _J @ h @ _J.T
    if not (np.linalg.eigvalsh(m) > 0).all():
        return None
    return np.linalg.inv(m), [info for _, _, info in solves]


def periodic_interval(space: Space, tensors: np.ndarray, cell_material: np.ndarray,
                      lo: np.ndarray, hi: np.ndarray, upper: dict[str, float],
                      image_axes: dict[str, int], tol: float, gap_target: float
                      ) -> tuple[dict[str, tuple[float, float]], dict[str, SolverInfo],
                                 list[str]]:
    """Per axis solved ``(lower, upper)``, the dual solves' reports and the sentence for a
    wide interval (empty when none; no interval when the lower bound is not finite).

    `upper`: per axis name, :func:`periodic_upper` of its solve; `image_axes`: the mesh
    axis of each name.
    """
    found = periodic_lower(space, tensors, cell_material, lo, hi, tol=tol)
    if found is None:
        return {}, {}, []
    low, infos = found
    interval = {n: (min(float(low[image_axes[n], image_axes[n]]), u), u)
                for n, u in upper.items()}
    wide = {a: g for a, g in relative_gaps(interval).items() if g > gap_target}
    notes: list[str] = []
    if wide:
        a = max(wide, key=lambda name: wide[name])
        notes.append(f"the periodic interval along {a} is {interval[a][0]:.6g} .. "
                     f"{interval[a][1]:.6g} (gap {100 * wide[a]:.3g} %), wider than the "
                     f"target {100 * gap_target:g} %, and the periodic protocol is not "
                     "refined for it (pass --refine): k_eff is certain only to within "
                     "that interval.")
    return interval, dict(zip(("periodic 0", "periodic 1"), infos)), notes
