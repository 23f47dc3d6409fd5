"""The up-scaled stochastic step: k_eff of random conductivity fields drawn from the signatures.

Segmentation measures, per material, the statistics of its tiles at the representative
elementary scale (RES): ``mean_mean`` (the mean tile-mean intensity) and ``mean_std`` (how
much the tile means vary from tile to tile). Here each material's intensity becomes a
stationary Gaussian field with that mean and standard deviation, correlated over the RES
tile size (squared-exponential covariance ``exp(-(r / l)^2)``, ``l`` the tile side;
:mod:`._random_field`), mapped to a conductivity by a given :class:`PropertyMap`:

``log-linear:a,b``
    ``log k = a + b * intensity``: a Gaussian intensity of mean ``m`` and std ``s`` gives
    a log-normal ``k`` with ``log k`` of mean ``a + b m`` and std ``|b| s`` (geometric
    mean ``exp(a + b m)``, arithmetic mean ``exp(a + b m + (b s)^2 / 2)``).

The materials' fields are independent. Each element takes the field at its centroid (the
nearest point of a grid of spacing ``l / 4`` over the box), so the conductivity is constant
per element; a label image is meshed with elements at most ``l / 2`` long (the field
varies over ``l``; no shorter than a voxel's diagonal), a mesh with elements longer than
``l`` along an axis is refused. Every realisation is
solved by the steady mixed-boundary protocol of :func:`~._simulate.simulate` (per-element
conductivity, P2 by default, no adaptation or interval), in blocks on Dask or here. P1 is
biased high by the element-wise field: +2.3 % for a 2-D log-normal field of log k std 1 at
two elements per correlation length, where P2 is within 0.3 % (0.6 % Monte-Carlo error).
Sample ``i`` draws its noise from ``SeedSequence(seed, spawn_key=(i,))``, so a run is
reproducible from its seed whatever the number of workers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Generator, Mapping
from dataclasses import dataclass
from numbers import Integral

import numpy as np

from .._steps import run_steps
from ..mesh import Mesh, mesh_labels
from ._assembly import cell_fluxes, fe_space, p1_embedding
from ._budget import DEFAULT_MEMORY, estimate_memory, format_bytes
from ._certify import check_memory_budget
from ._pmultigrid import stiffness_operator
from ._protocols import check_within_bounds, mixed_boundary, voigt_reuss
from ._random_field import gaussian_field
from ._simulate import _check_axes, _check_box_faces, check_tolerance
from ._solve import DEFAULT_TOLERANCE, element_parts
from ._stochastic_dask import run_blocks
from ._stochastic_laws import (
    MAPS,
    PropertyMap,
    fixed_tensors,
    material_laws,
    parse_property_map,
    signature_tile_size,
)
from ._stochastic_result import StochasticResult

__all__ = ["MAPS", "POINTS_PER_LENGTH", "PropertyMap", "StochasticResult",
           "parse_property_map", "signature_tile_size", "stochastic_k_eff",
           "stochastic_steps"]

POINTS_PER_LENGTH = 4          # field grid points per correlation length
ELEMENTS_PER_LENGTH = 2        # elements per correlation length, at least


def _check_count(value, what: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
        raise ValueError(f"{what} must be a whole number of at least {low}, not {value!r}.")
    return int(value)


@dataclass(frozen=True)
class _Problem:
    """What every block needs: the mesh, the field grid and the per-material laws."""

    mesh: Mesh
    grid: tuple[int, ...]
    spacing: np.ndarray
    correlation: np.ndarray
    nearest: np.ndarray          # (M,) flat index of each centroid's grid point
    random: tuple                # ((label, log mean, log std), ...)
    fixed: np.ndarray            # (M, d, d) tensors of the fixed materials (0 elsewhere)
    axes: tuple[str, ...]
    order: int
    tol: float
    seed: int


def _log_k(problem: _Problem, index: int | None, field) -> np.ndarray:
    """(M,) log k of sample `index` (None: every field at 0, the mean intensities)."""
    mesh = problem.mesh
    out = np.zeros(mesh.n_cells)
    rng = (None if index is None else
           np.random.default_rng(np.random.SeedSequence(problem.seed, spawn_key=(index,))))
    for label, mean, std in problem.random:
        cells = mesh.material == label
        out[cells] = mean
        if rng is not None:                 # one field per material, drawn in label order
            z = field.sample(rng).ravel()
            out[cells] += std * z[problem.nearest[cells]]
    return out


def _solve_block(problem: _Problem, indices) -> np.ndarray:
    """(len(indices), n_axes + 2) k_eff of the samples `indices` (None: the mean
    intensities) per axis, then the volume-weighted mean and variance of their log k over
    the random materials.

    On one BLAS thread: the parallelism is across samples, and the multigrid's dense
    bottom-level pseudo-inverse ran ten times slower on two threads of a busy machine.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:                      # not a dependency: then as BLAS is set up
        return _solve_samples(problem, indices)
    with threadpool_limits(1, user_api="blas"):
        return _solve_samples(problem, indices)


def _solve_samples(problem: _Problem, indices) -> np.ndarray:
    mesh, d = problem.mesh, problem.mesh.ndim
    field = gaussian_field(problem.grid, problem.spacing, problem.correlation)
    space = fe_space(mesh, problem.order)
    doflocs, coarse = space.doflocs, p1_embedding(space)
    lo, hi = mesh.image_box()
    cells = np.arange(mesh.n_cells)
    random = np.isin(mesh.material, [r[0] for r in problem.random])
    out = np.empty((len(indices), len(problem.axes) + 2))
    parts = element_parts(mesh.cells, len(mesh.points), space.edges)
    for row, index in enumerate(indices):
        tensors = problem.fixed.copy()
        log_k = _log_k(problem, index, field)
        tensors[random] = np.exp(log_k[random])[:, None, None] * np.eye(d)
        volumes = np.empty(mesh.n_cells)
        # the deterministic solve's operator (P2 in half storage): the same k_eff, bit
        # for bit, when the fields have no variance
        matrix = stiffness_operator(space, tensors, cells, volumes)
        fractions = np.abs(volumes) / float(np.prod(hi - lo))
        weights = fractions[random] / fractions[random].sum()
        log_mean = float(weights @ log_k[random])
        out[row, -2:] = log_mean, float(weights @ (log_k[random] - log_mean) ** 2)

        def energy(u, tensors=tensors):
            return cell_fluxes(space, u, tensors, cells)[1]

        for col, name in enumerate(problem.axes):
            result = mixed_boundary(matrix, doflocs, name, lo, hi, energy, tol=problem.tol,
                                    parts=parts, cell_dofs=space.element_dofs,
                                    cell_material=mesh.material, coarse=coarse)
            axis = d - 1 - "xyz".index(name)
            voigt, reuss = voigt_reuss(tensors, fractions, axis)
            check_within_bounds(result.k_eff, voigt, reuss, name)
            out[row, col] = result.k_eff
    return out


def stochastic_steps(mesh_or_labels, signatures, *, samples: int, correlation,
                     property_map="log-linear:0,1", seed: int = 0,
                     conductivity: Mapping | None = None, spacing=None, exclude=(),
                     material_names: Mapping[int, str] | None = None, refine: int = 0,
                     max_size: float | None = None, order: int = 2, axes=None,
                     tol: float = DEFAULT_TOLERANCE, workers: int = 1,
                     scheduler: str | None = None, client=None,
                     memory: float = DEFAULT_MEMORY
                     ) -> Generator[tuple[int, int, str], None, StochasticResult]:
    """Run :func:`stochastic_k_eff` step by step, for a progress bar.

    Parameters
    ----------
    mesh_or_labels, signatures, samples, correlation, property_map, seed, conductivity,
    spacing, exclude, material_names, refine, max_size, order, axes, tol, workers,
    scheduler, client, memory
        As for :func:`stochastic_k_eff`.

    Yields
    ------
    (done, total, message) : (int, int, str)
        Progress: the mesh, the mean-intensity solve, then blocks of samples.

    Returns
    -------
    StochasticResult
        As the generator's return value (``StopIteration.value``).
    """
    samples = _check_count(samples, "samples", 2)
    workers = _check_count(workers, "workers", 1)
    seed = _check_count(seed, "seed", 0)
    prop = parse_property_map(property_map)
    check_tolerance(tol)
    check_memory_budget(memory)
    if isinstance(order, bool) or order not in (1, 2):
        raise ValueError(f"order must be 1 or 2 (P1 or P2 elements), not {order!r}.")
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    if isinstance(mesh_or_labels, Mesh):
        mesh = mesh_or_labels
        if material_names:
            mesh = mesh.with_material_names({**mesh.material_names, **material_names})
        d = mesh.ndim
    else:
        d = np.ndim(mesh_or_labels)
    ell = np.broadcast_to(np.asarray(correlation, dtype=np.float64), (d,)).copy()
    if not (np.isfinite(ell).all() and (ell > 0).all()):
        raise ValueError(f"the correlation length (the RES tile size) must be positive, "
                         f"not {np.asarray(correlation).tolist()}.")
    longest = float(ell.min()) / ELEMENTS_PER_LENGTH
    if max_size is not None and not (math.isfinite(max_size) and max_size > 0):
        raise ValueError(f"max_size must be a positive length, not {max_size!r}.")
    if isinstance(mesh_or_labels, Mesh) and (spacing is not None or tuple(exclude) or refine
                                             or max_size is not None):
        raise ValueError("spacing, exclude, refine and max_size apply to a label image; a "
                         "mesh already has them.")
    names = _check_axes(axes, d)
    if isinstance(mesh_or_labels, Mesh):
        present, mesh_names = np.unique(mesh.material).tolist(), mesh.material_names
    else:                      # the materials checked from the labels, before meshing
        present = sorted(set(np.unique(np.asarray(mesh_or_labels)).tolist())
                         - {int(e) for e in exclude})
        mesh_names = {int(k): str(v) for k, v in dict(material_names or {}).items()}
    random, fixed, table, rows = material_laws(signatures, present, mesh_names, conductivity,
                                               prop, d)
    if not random:
        raise ValueError("every material has a fixed conductivity: nothing is random; leave "
                         "--conductivity out for the materials the signatures describe.")
    if not isinstance(mesh_or_labels, Mesh):
        yield 0, samples + 2, "meshing the labels"
        # no shorter than a voxel's diagonal: the field is then resolved voxel by voxel
        voxel = float(np.linalg.norm(np.broadcast_to(
            np.asarray(1.0 if spacing is None else spacing, dtype=np.float64), (d,))))
        mesh = mesh_labels(mesh_or_labels, spacing=spacing, exclude=exclude,
                           material_names=dict(material_names or {}), refine=refine,
                           max_size=max(voxel, min(longest, max_size or longest)))
    edges = mesh.points[mesh.cells]                                    # (M, d + 1, d)
    span = (edges.max(axis=1) - edges.min(axis=1)) / ell               # (M, d) in lengths
    if float(span.max()) > 1 + 1e-9:
        raise ValueError(f"the mesh has elements {span.max():.3g} correlation lengths long: "
                         "the field would be averaged away within them; mesh with "
                         f"swa-imesh mesh --max-size {ell.min() / ELEMENTS_PER_LENGTH:.3g} "
                         "(or simulate the labels).")
    at_once = workers if client is None and scheduler is None else 1
    need = estimate_memory(mesh, order, False) * at_once
    if need > memory:
        raise ValueError(f"{at_once} solve(s) at once on {mesh.n_cells} elements need about "
                         f"{format_bytes(need)}, above the memory budget of "
                         f"{format_bytes(memory)}: use fewer workers, a longer tile size, "
                         "or raise --memory.")
    cell_tensors = fixed_tensors(mesh, fixed, table)
    lo, hi = mesh.image_box()
    if not mesh.records_box:
        _check_box_faces(mesh, names, lo, hi)
    h = ell / POINTS_PER_LENGTH
    grid = tuple(int(n) for n in np.floor((hi - lo) / h + 0.5) + 1)
    centroids = edges.mean(axis=1)
    nearest = np.clip(np.rint((centroids - lo) / h).astype(np.int64), 0, np.array(grid) - 1)
    problem = _Problem(mesh, grid, h, ell, np.ravel_multi_index(nearest.T, grid), random,
                       cell_tensors, names, order, float(tol), seed)
    gaussian_field(grid, h, ell)                # refuse an embedding too large, here
    seconds["mesh"] = time.perf_counter() - t0
    total = samples + 2
    yield 1, total, f"solving at the mean intensities ({mesh.n_cells} elements)"
    t0 = time.perf_counter()
    mean_field = _solve_block(problem, [None])[0]
    seconds["mean"] = time.perf_counter() - t0
    # here, one sample per step (Cancel answers after one solve); on Dask, blocks of a few
    # samples, some per worker for balance, each building the FE space once
    here = client is None and scheduler is None and workers <= 1
    size = 1 if here else max(1, min(16, samples // (4 * workers)))
    blocks = [list(range(i, min(i + size, samples))) for i in range(0, samples, size)]
    values = np.empty((samples, len(names) + 2))
    done = 2
    t0 = time.perf_counter()
    yield done, total, f"solving {samples} samples"
    for i, block_values in run_blocks(_solve_block, problem, blocks, workers=workers,
                                      scheduler=scheduler, client=client):
        values[blocks[i]] = np.asarray(block_values)
        done += len(blocks[i])
        yield done, total, f"{done - 2} of {samples} samples solved"
    seconds["samples"] = time.perf_counter() - t0
    return StochasticResult(
        samples={n: values[:, j].copy() for j, n in enumerate(names)},
        log_k_moments=values[:, -2:].copy(),
        at_mean={n: float(mean_field[j]) for j, n in enumerate(names)},
        materials=rows, property_map=str(prop), correlation=tuple(ell.tolist()),
        seed=seed, order=order, n_cells=mesh.n_cells, seconds=seconds, workers=workers,
        scheduler=scheduler)


def stochastic_k_eff(mesh_or_labels, signatures, *, samples: int, correlation,
                     property_map="log-linear:0,1", seed: int = 0,
                     conductivity: Mapping | None = None, spacing=None, exclude=(),
                     material_names: Mapping[int, str] | None = None, refine: int = 0,
                     max_size: float | None = None, order: int = 2, axes=None,
                     tol: float = DEFAULT_TOLERANCE, workers: int = 1,
                     scheduler: str | None = None, client=None,
                     memory: float = DEFAULT_MEMORY) -> StochasticResult:
    """Monte-Carlo k_eff of random conductivity fields drawn from the material signatures.

    Parameters
    ----------
    mesh_or_labels : Mesh or (M, N[, P]) array_like of int
        A mesh with a material per element (elements at most one correlation length
        along each axis), or a label image to mesh (elements at most half the
        correlation length, or `max_size` if shorter, but not below a voxel's diagonal).
    signatures : str, Path or sequence of mapping
        The signatures CSV (``swa-imesh segment --signatures``) or its rows: ``label``
        and/or ``name``, ``mean_mean`` and ``mean_std`` per material.
    samples : int
        Realisations to solve (at least 2).
    correlation : float or sequence of float
        Correlation length per axis in array order, physical units: the RES tile side
        (``2**scale`` voxels times the spacing).
    property_map : str or PropertyMap
        ``"log-linear:a,b"``: ``log k = a + b * intensity``.
    seed : int
        Seed of every field (sample ``i`` uses ``SeedSequence(seed, spawn_key=(i,))``).
    conductivity : mapping, optional
        Fixed conductivities (as for :func:`~._simulate.simulate`) of materials that are
        not to be random; every other material needs its signature row.
    spacing, exclude, material_names, refine
        As for :func:`~._simulate.simulate` (spacing, exclude and refine: labels only).
    max_size : float, optional
        Labels only: longest element edge, if shorter than half the correlation length.
    order : {1, 2}
        Lagrange element degree (default 2: P1's conforming solution on element-wise
        constant conductivity is biased high, about 2 % at a log k std of 1).
    axes : sequence of {"x", "y", "z"}, optional
        Axes to solve along (default all).
    tol : float
        Relative residual of each linear solve.
    workers : int
        1: solve here; more: a local Dask cluster of that many processes.
    scheduler : str, optional
        Address of a running Dask scheduler to use instead.
    client : distributed.Client, optional
        An open client to use instead (left open).
    memory : float
        Budget in bytes (default 4 GiB) of the solves running at once here or on the
        local workers (one sample each at a time), checked from the mesh before any
        solve; on a scheduler, of one solve.

    Returns
    -------
    StochasticResult

    Examples
    --------
    One material with no spread: every sample is the deterministic k_eff, exp(0) = 1.

    >>> rows = [{"label": 1, "name": "a", "mean_mean": 0.0, "mean_std": 0.0}]
    >>> r = stochastic_k_eff(np.ones((4, 4), dtype=int), rows, samples=2, correlation=2.0)
    >>> r.samples["x"].round(9).tolist()
    [1.0, 1.0]
    """
    steps = stochastic_steps(mesh_or_labels, signatures, samples=samples,
                             correlation=correlation, property_map=property_map, seed=seed,
                             conductivity=conductivity, spacing=spacing, exclude=exclude,
                             material_names=material_names, refine=refine,
                             max_size=max_size, order=order, axes=axes, tol=tol,
                             workers=workers, scheduler=scheduler, client=client,
                             memory=memory)
    return run_steps(steps)
