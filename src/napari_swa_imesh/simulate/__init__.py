"""Step iv of the pipeline: transport on the mesh, effective properties of the image.

* :func:`simulate` (and :func:`simulate_steps` for progress): steady diffusion with one
  conductivity per material (number, diagonal or tensor), P1 or P2 elements assembled by
  our vectorised code (:mod:`._assembly`, checked against scikit-fem), solved by
  conjugate gradients with smoothed-aggregation multigrid (:mod:`._amg`); the
  mixed-boundary effective conductivity per axis, or the full tensor by the periodic
  protocol, checked against its Voigt-Reuss bounds; for the mixed protocol a certified
  interval (:mod:`._dual`: the conforming energy above, the complementary energy of an
  exactly divergence-free flux below), refined until within 2 % where the budget
  (:mod:`._budget`, in bytes) allows;
* :func:`solve_boundary_value`: one steady problem with Dirichlet, Neumann and Robin
  conditions on the mesh's named facet groups and volume sources;
* :func:`simulate_transient` (and :func:`transient_steps`): a heat front from a face or a
  substance released from a material, the mesh and the time steps chosen for an asked
  error and the error estimated (:mod:`._transient_space`, :mod:`._time_steps`);
* :func:`simulate_growth` (and :func:`growth_steps`): reaction-diffusion, tumour growth
  (Fisher-KPP) or drug delivery, with a diffusivity per material, bounded adaptive
  IMEX steps and the amount's balance; :func:`write_growth` and :func:`growth_table`
  for the series, the volume and front table and its plot;
* :func:`conductivity_tensors`, :func:`parse_conductivity_args`: the conductivity table;
* :func:`stochastic_k_eff` (and :func:`stochastic_steps`): k_eff of random conductivity
  fields drawn from the signatures (the up-scaled stochastic step), in parallel on Dask;
* :func:`simulation_report` (with :func:`read_signatures`, :func:`write_report`): the
  per-material signatures of the segmentation and k_eff in one table.
"""

from ._adapt import P1_GROWTH
from ._boundary import BoundaryResult, solve_boundary_value
from ._conductivity import conductivity_tensors, material_label, parse_conductivity_args
from ._growth import GROWTH_MODELS, GrowthResult, growth_steps, simulate_growth
from ._growth_output import growth_table, write_growth
from ._output import write_field, write_series
from ._random_field import GaussianField, gaussian_field
from ._remesh import mesh_refine, needs_remesh, remesh
from ._report import SimulationReport, read_signatures, simulation_report, write_report
from ._simulate import SimulationResult, simulate, simulate_steps
from ._solve import SolverInfo
from ._stochastic import (
    PropertyMap,
    parse_property_map,
    signature_tile_size,
    stochastic_k_eff,
    stochastic_steps,
)
from ._stochastic_result import StochasticResult, check_stochastic_paths, write_stochastic
from ._transient import TransientResult, simulate_transient, transient_steps

__all__ = ["BoundaryResult", "SimulationReport", "SimulationResult", "SolverInfo",
           "TransientResult", "conductivity_tensors", "parse_conductivity_args",
           "read_signatures", "simulate", "simulate_steps", "simulate_transient",
           "simulation_report", "solve_boundary_value", "transient_steps", "write_field",
           "write_report", "write_series",
           # for the widgets and the pipeline (issue 24)
           "P1_GROWTH", "material_label", "mesh_refine", "needs_remesh", "remesh",
           # reaction-diffusion (issue 28)
           "GROWTH_MODELS", "GrowthResult", "growth_steps", "growth_table", "simulate_growth",
           "write_growth"]
# the stochastic step (issue 28, part 2)
__all__ += ["GaussianField", "PropertyMap", "StochasticResult", "check_stochastic_paths",
            "gaussian_field", "parse_property_map", "signature_tile_size",
            "stochastic_k_eff", "stochastic_steps", "write_stochastic"]
