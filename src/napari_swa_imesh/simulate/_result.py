"""The result of :func:`~._simulate.simulate`: k_eff, its bounds and interval, the fields."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..mesh import Mesh
from ._budget import DEFAULT_MEMORY, format_bytes
from ._certify import GAP_TARGET, relative_gaps
from ._hashin import HashinShtrikman
from ._solve import SolverInfo

__all__ = ["SimulationResult"]


@dataclass
class SimulationResult:
    """Effective conductivity of the image box, with the fields that give it.

    Axis names follow the mesh files: x = column, y = row, z = plane.

    Attributes
    ----------
    k_eff : dict of str to float
        Mixed-boundary effective conductivity per axis solved.
    bounds : dict of str to (float, float)
        Reuss (harmonic) and Voigt (arithmetic) means per axis; k_eff lies between them.
    potential : dict of str to (N,) ndarray
        The potential (0 on the ``min`` face, 1 on the ``max`` face) at the mesh vertices.
    flux : dict of str to (M, d) ndarray
        ``-C grad u`` per element, components in x, y(, z) order.
    solver : dict of str to SolverInfo
    volume_fractions : dict of int to float
        Per material, of the box volume.
    mesh : Mesh
    order : int
        Element degree (1 or 2).
    dofs : int
        Degrees of freedom of one solve.
    seconds : dict of str to float
        Per step: ``mesh``, ``assemble``, ``solve``; ``setup``: of ``solve``, the
        multigrid set-up (``solve`` minus ``setup`` is the iterations and the fluxes).
    protocol : {"mixed", "periodic"}
        How k_eff was found (see :func:`simulate`).
    tensor : (d, d) ndarray or None
        Periodic protocol: the full effective tensor in x, y(, z) order (column i: the
        mean flux, as a conductivity, under a unit mean gradient along axis i; NaN for
        axes not solved).
    hashin_shtrikman : HashinShtrikman or None
        Two isotropic materials filling the box: their Hashin-Shtrikman bounds, and with
        the periodic protocol on every axis the trace inequalities of ``tensor`` (the form
        that holds for anisotropic microstructures; :mod:`._hashin`).
    adapt : int
        Adaptive refinement steps taken before the final solve (:mod:`._adapt`).
    choice : str
        The elements and steps used, and why when the default chose them.
    interval : dict of str to (float, float)
        Mixed protocol: per axis (lower, upper) bounds of the exact k_eff of the meshed
        geometry (the dual and primal energies; upper = ``k_eff``); empty otherwise.
    gap_target : float
        The relative width asked; :attr:`gap` gives the reached one.
    certify : int
        Refinement steps taken to narrow the interval.
    dual_solver : dict of str to SolverInfo
        The dual (Crouzeix-Raviart) solves.
    warnings : list of str
        Sentences about the result (an interval left wider than the target).
    memory_estimate : int
        Estimated peak bytes of the final solve (:mod:`._budget`), checked against
    memory : float
        the budget, before assembly.
    """

    k_eff: dict[str, float]
    bounds: dict[str, tuple[float, float]]
    potential: dict[str, np.ndarray]
    flux: dict[str, np.ndarray]
    solver: dict[str, SolverInfo]
    volume_fractions: dict[int, float]
    mesh: Mesh
    order: int
    dofs: int
    seconds: dict[str, float] = field(default_factory=dict)
    protocol: str = "mixed"
    tensor: np.ndarray | None = None
    hashin_shtrikman: HashinShtrikman | None = None
    adapt: int = 0
    choice: str = ""
    interval: dict[str, tuple[float, float]] = field(default_factory=dict)
    gap_target: float = GAP_TARGET
    certify: int = 0
    dual_solver: dict[str, SolverInfo] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    memory_estimate: int = 0
    memory: float = DEFAULT_MEMORY

    @property
    def gap(self) -> dict[str, float]:
        """Per axis, the interval's relative width ``(upper - lower) / lower``."""
        return relative_gaps(self.interval)

    def summary(self) -> dict:
        """Plain-JSON summary (what ``swa-imesh simulate --json`` prints)."""
        return {
            "k_eff": dict(self.k_eff),
            "bounds": {a: {"reuss": lo, "voigt": hi} for a, (lo, hi) in self.bounds.items()},
            "volume_fractions": {str(k): v for k, v in self.volume_fractions.items()},
            "order": self.order,
            "adapt": self.adapt,
            "choice": self.choice,
            "dofs": self.dofs,
            "elements": self.mesh.n_cells,
            "iterations": {a: s.iterations for a, s in self.solver.items()},
            "residual": max((s.residual for s in self.solver.values()), default=0.0),
            "seconds": dict(self.seconds),
            "protocol": self.protocol,
            **({"tensor": [[None if np.isnan(v) else float(v) for v in row]
                           for row in self.tensor]} if self.tensor is not None else {}),
            **({"hashin_shtrikman": self.hashin_shtrikman.to_dict()}
               if self.hashin_shtrikman is not None else {}),
            **({"interval": {a: {"lower": lo, "upper": hi, "gap": self.gap[a]}
                             for a, (lo, hi) in self.interval.items()},
                "gap_target": self.gap_target, "certify": self.certify}
               if self.interval else {}),
            "warnings": list(self.warnings),
            "memory_estimate_bytes": self.memory_estimate,
            "memory_budget_bytes": self.memory,
        }

    def describe(self) -> str:
        """A few lines for people: k_eff per axis within its bounds, the solve's cost."""
        lines = [f"steady diffusion, P{self.order} on {self.mesh.n_cells} elements, "
                 f"{self.dofs} unknowns, {self.protocol} protocol"
                 + (f" ({self.choice})" if self.choice else "")]
        for a, k in self.k_eff.items():
            lo, hi = self.bounds[a]
            s = self.solver[a]
            lines.append(f"k_eff {a} = {k:.6g}  (Reuss {lo:.4g} .. Voigt {hi:.4g}; "
                         f"{s.iterations} CG iterations, residual {s.residual:.1e})")
        for a, (lo, hi) in self.interval.items():
            lines.append(f"certified {a}: {lo:.6g} <= k_eff <= {hi:.6g}  (gap "
                         f"{100 * self.gap[a]:.3g} %, target {100 * self.gap_target:g} %)")
        if self.protocol == "periodic" and not self.interval:
            lines.append("no certified interval: the periodic protocol has one in 2-D only "
                         "(and not with --no-interval)")
        lines += [f"warning: {w}" for w in self.warnings]
        if self.memory_estimate:
            lines.append(f"memory: estimated peak {format_bytes(self.memory_estimate)} "
                         f"(budget {format_bytes(self.memory)}, checked before assembly)")
        fractions = ", ".join(f"{self.mesh.material_names.get(m, m)} {f:.3f}"
                              for m, f in self.volume_fractions.items())
        lines.append(f"volume fractions: {fractions}")
        if self.tensor is not None:
            lines.append("tensor (x, y(, z)):")
            lines += ["  " + "  ".join(f"{v:11.6g}" for v in row) for row in self.tensor]
        hs = self.hashin_shtrikman
        if hs is not None:
            line = (f"Hashin-Shtrikman (two phases, for an isotropic microstructure): "
                    f"{hs.lower:.4g} .. {hs.upper:.4g}")
            if hs.trace_holds is not None:
                line += ("; trace bounds of the tensor: lower "
                         + ("holds" if hs.trace_holds[0] else "FAIL") + ", upper "
                         + ("holds" if hs.trace_holds[1] else "crossed (discretisation "
                            "error near an optimal microstructure)"))
            lines.append(line)
        return "\n".join(lines)
