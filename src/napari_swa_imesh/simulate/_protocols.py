"""Up-scaling protocols: effective conductivity of the image box, and its bounds.

Mixed-boundary protocol along axis a: potential 0 on the face ``a = min``, 1 on the face
``a = max``, every other boundary insulated (zero flux). The effective conductivity is

    k_eff = Q * L / A,

with Q the flux through the box, L the box length along a and A the area of the face. Q
is the dissipated energy ``int grad u . C grad u`` (for the discrete solution it equals
the sum of the reactions on either face; the energy is a sum of positive terms and
stationary at the solution, so it stays accurate at contrasts where the reaction sums
cancel away; the reactions are kept as a check). Materials left out of the mesh
(``--exclude``) carry no flux: the box, not the mesh, defines L and A.

For this protocol the discrete k_eff is bracketed by Voigt (arithmetic mean: the linear
potential is in the finite-element space, so the discrete energy is below its energy)
and Reuss (harmonic mean: a uniform flux along a is admissible for the complementary
principle, and the discrete solution is stiffer than the exact one). A result outside
them is a bug, and is refused.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ._solve import DirichletSolver, SolverInfo, check_constrained

__all__ = ["MixedResult", "face_dofs", "face_names", "mixed_boundary",
           "voigt_reuss"]

BOUND_SLACK = 1e-6               # relative; far above the solver's 1e-10 residual
FLUX_AGREEMENT = 1e-6            # relative; a converged solve agrees to about 1e-10
RETRY_FACTOR = 1e-3              # a disagreeing solve is continued to tol times this


@dataclass(frozen=True)
class MixedResult:
    """One mixed-boundary solve along one axis.

    Attributes
    ----------
    k_eff : float
        Effective conductivity along the axis.
    values : (n_dofs,) ndarray
        The potential at every degree of freedom.
    flux_in, flux_out : float
        Sum of the reactions on the ``max`` and ``min`` faces (each equals the energy up
        to the solver's tolerance at moderate contrast; at least one of them must).
    info : SolverInfo
    """

    k_eff: float
    values: np.ndarray
    flux_in: float
    flux_out: float
    info: SolverInfo


def face_names(ndim: int) -> tuple[str, ...]:
    """The box faces in the FE frame: ``xmin, xmax, ymin, ymax(, zmin, zmax)``."""
    return tuple(f"{a}{end}" for a in "xyz"[:ndim] for end in ("min", "max"))


def face_dofs(dof_coordinates: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              face: str) -> np.ndarray:
    """Degrees of freedom on one face of the box (``"xmin"`` ... ``"zmax"``).

    Mesh axes: x = column (last image axis), y = row, z = plane.
    """
    d = lo.size
    if face not in face_names(d):
        raise ValueError(f"unknown face {face!r}; the faces of a {d}-D box are "
                         f"{', '.join(face_names(d))}.")
    axis = d - 1 - "xyz".index(face[0])
    eps = 1e-9 * (hi[axis] - lo[axis])
    coord = dof_coordinates[axis]
    if face.endswith("min"):
        return np.flatnonzero(coord <= lo[axis] + eps)
    return np.flatnonzero(coord >= hi[axis] - eps)


def mixed_boundary(matrix, dof_coordinates: np.ndarray, name: str, lo: np.ndarray,
                   hi: np.ndarray, energy: Callable[[np.ndarray], float], *, tol: float,
                   parts: np.ndarray | None = None,
                   cell_dofs: np.ndarray | None = None,
                   cell_material: np.ndarray | None = None,
                   coarse=None) -> MixedResult:
    """Solve the mixed-boundary protocol along `axis` and return k_eff.

    Parameters
    ----------
    matrix : (n, n) sparse matrix
        Assembled stiffness.
    dof_coordinates : (d, n) ndarray
        Coordinates of the degrees of freedom (scikit-fem's ``basis.doflocs``).
    name : {"x", "y", "z"}
        The axis (x = column, y = row, z = plane).
    lo, hi : (d,) ndarray
        Corners of the box.
    energy : callable
        ``u -> int grad u . C grad u`` summed element by element (:func:`dissipation`);
        k_eff comes from it, the face reactions only check it.
    parts, cell_dofs, cell_material : ndarray, optional
        Connected parts of the dofs (:func:`connected_parts`) to refuse a part that
        touches neither face, and the element tables that name its materials.
    coarse : (n, n_vertices) sparse matrix, optional
        P2: the P1 functions (:func:`~._assembly.p1_embedding`), the multigrid's first
        coarse level.

    Raises
    ------
    ValueError
        A face no material touches, a floating part, or a solve whose face fluxes both
        disagree with its energy (the conductivity contrast is beyond what the solver
        reached).
    """
    axis = lo.size - 1 - "xyz".index(name)
    length = hi[axis] - lo[axis]
    low = face_dofs(dof_coordinates, lo, hi, f"{name}min")
    high = face_dofs(dof_coordinates, lo, hi, f"{name}max")
    for face, dofs in (("min", low), ("max", high)):
        if dofs.size == 0:
            raise ValueError(f"no meshed material touches the {name}{face} face, so no "
                             f"flux can cross the box along {name}; crop the image or "
                             "mesh the material on that face.")
    fixed = np.concatenate([low, high])
    if parts is not None:
        check_constrained(parts, fixed, f"the {name} faces", cell_dofs, cell_material)
    values = np.concatenate([np.zeros(low.size), np.ones(high.size)])
    problem = DirichletSolver(matrix, fixed, tol=tol, coarse=coarse)
    u, info = problem.solve(values)
    flux_in, flux_out, flux, agreement = _face_fluxes(matrix, u, low, high, energy)
    if not agreement <= FLUX_AGREEMENT:
        # at contrasts near 1e12 the residual test can be met while the reactions on a
        # face still differ in the sixth digit: continue the same solve further once
        u, more = problem.solve(values, x0=u, tol=tol * RETRY_FACTOR)
        info = SolverInfo(info.unknowns, info.iterations + more.iterations, more.residual,
                          info.seconds + more.seconds, info.setup)
        flux_in, flux_out, flux, agreement = _face_fluxes(matrix, u, low, high, energy)
    if not agreement <= FLUX_AGREEMENT:
        raise ValueError(f"along {name} the flux through the faces ({flux_in:.6g}, "
                         f"{flux_out:.6g}) disagrees with the dissipated energy "
                         f"({flux:.6g}): the solve did not converge far enough for this "
                         "conductivity contrast; lower --tol or the contrast.")
    area = float(np.prod(np.delete(hi - lo, axis)))
    return MixedResult(float(flux * length / area), u, flux_in, flux_out, info)


def _face_fluxes(matrix, u: np.ndarray, low: np.ndarray, high: np.ndarray,
                 energy: Callable[[np.ndarray], float]) -> tuple[float, float, float, float]:
    """Reactions on the max and min faces, the energy, and their best relative agreement."""
    reaction = matrix @ u
    flux_in = float(reaction[high].sum())
    flux_out = float(-reaction[low].sum())
    flux = energy(u)                                  # = flux x (potential difference 1)
    return flux_in, flux_out, flux, min(abs(flux_in - flux), abs(flux_out - flux)) / flux


def voigt_reuss(tensors: np.ndarray, fractions: np.ndarray, axis: int
                ) -> tuple[float, float]:
    """Arithmetic (Voigt) and harmonic (Reuss) means of the conductivity along `axis`.

    Parameters
    ----------
    tensors : (n, d, d) ndarray
        Conductivity per material, in the mesh's axis order.
    fractions : (n,) ndarray
        Volume fraction of each material in the box; ``1 - sum`` is excluded
        (non-conducting), which makes the harmonic mean 0.
    """
    voigt = float(np.sum(fractions * tensors[:, axis, axis]))
    # volumes summed over millions of elements round off by about 1e-11 of the box
    if fractions.sum() < 1 - 1e-9:
        return voigt, 0.0
    inverse = np.linalg.inv(tensors)[:, axis, axis]
    return voigt, float(1.0 / np.sum(fractions * inverse))


def check_within_bounds(k_eff: float, voigt: float, reuss: float, axis_name: str) -> None:
    """Refuse a k_eff outside the bounds every conforming discrete solution satisfies."""
    if not (reuss * (1 - BOUND_SLACK) <= k_eff <= voigt * (1 + BOUND_SLACK)):
        raise ValueError(f"k_eff along {axis_name} = {k_eff:.6g} lies outside the Voigt-"
                         f"Reuss bounds [{reuss:.6g}, {voigt:.6g}]: the mesh or the solve "
                         "is wrong; please report this with the input.")
