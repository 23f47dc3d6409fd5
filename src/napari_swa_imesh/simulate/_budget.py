"""The memory budget of a steady run, in bytes, estimated from the mesh before assembly.

A budget in unknowns does not say whether a run fits: P2 at 128^3 was within its unknowns
and killed at 8 GB. The estimate here is the peak of one solve, measured per unknown on
IMESH meshes of three-phase blobs (P1, P2 and the Crouzeix-Raviart dual of
:mod:`._dual`: matrix, multigrid hierarchy, vectors and the element passes), plus what
the result keeps (the mesh, a flux and a potential per axis). The counts of unknowns come
from the mesh's vertices and elements by Euler's relation (edges ~ vertices + elements,
facets ~ (d + 1) / 2 elements), so nothing is assembled to know the cost.
"""

from __future__ import annotations

from ..mesh import Mesh

__all__ = ["DEFAULT_MEMORY", "check_memory", "estimate_memory", "fit_interval",
           "format_bytes", "parse_memory"]

#: Default budget of a steady run (bytes): a sixth of this 24 GB machine.
DEFAULT_MEMORY = 4 * 2 ** 30
#: Peak bytes per unknown of one solve, measured at 40^3 (three-phase blobs, contrast
#: 1e4, one axis; peak RSS less the interpreter's 78 MB): P1 2260 (65k vertices, 140 MB),
#: P2 with its matrix assembled 1550 (451k unknowns, 666 MB; the adapted 20^3 default:
#: 1560 for 433k, issue 26's 64^3 default 1300); 2-D taken alike (its rows are shorter).
#: The periodic protocol still assembles P2 (it needs the matrix's rows).
BYTES_PER_UNKNOWN = {(2, 1): 2300.0, (2, 2): 1600.0, (3, 1): 2300.0, (3, 2): 1600.0}
#: P2 of the mixed protocol, held as half a matrix with a p-multigrid onto P1
#: (:mod:`._pmultigrid`), fixed bytes plus bytes per unknown, fitted to the peak RSS of
#: ``swa-imesh simulate --order 2 --adapt 0 --no-interval`` on bench_scaling's blobs
#: (`MEASURED_HALF`; the batches summed as they come, the solve's vectors made once):
#: 32^3 0.41 GiB, 48^3 0.64, 64^3 0.97 (1.38M unknowns), 128^3 4.43 GiB (7.52M; 5.03
#: before, with the assembly's batches the peak): a line through 32^3 and 128^3 raised by
#: 5 %, so 320 MiB + 548 B per unknown, 5-14 % above each (earlier 256 MB + 750 B: 6.0 GB
#: printed at 128^3).
BYTES_PER_UNKNOWN_HALF = {2: 548.0, 3: 548.0}
BYTES_HALF_FIXED = 320 * 2 ** 20
#: The peaks the half-storage constants are fitted to: (unknowns as :func:`unknowns`
#: counts them, elements, peak bytes); then 96^3 with the int32 tables and the Lanczos
#: and Dirichlet steps in place, 2.12 GiB for an estimate of 2.50, and 128^3 again with
#: them, 4.00 GiB for 4.65.
MEASURED_HALF = ((220_877, 155_413, 438_206_464), (659_676, 469_220, 684_453_888),
                 (1_383_626, 989_328, 1_043_529_728), (7_520_597, 5_415_021, 4_751_519_744),
                 (3_788_123, 2_721_553, 2_274_037_760),
                 (7_520_597, 5_415_021, 4_293_361_664))
#: The dual's CR solve, per facet (measured 565 at 40^3: 625k facets, 353 MB with the
#: primal matrix kept). 3-D refitted: ``--order 2 --adapt 0`` with the interval on 64^3
#: three-phase blobs of sigma 3 (bench_simulate's) peaks in the dual's multigrid set-up
#: at 1.59 GiB (2.24M facets, 1.58M P2 unknowns; 1.73 GiB before the solve's changes),
#: 706 B per facet with the rest of the estimate: 750 (600 put it at 1.37 GiB, below);
#: 128^3 of those blobs peaked at 11.8 GiB (18.0M facets; 600 said 11.0, 750 says 13.5).
BYTES_PER_FACET = {2: 600.0, 3: 750.0}
#: The peaks with the interval those are checked against: (elements, P2 unknowns as
#: :func:`unknowns` counts them, peak bytes); the 128^3 one is of the code before.
MEASURED_DUAL = ((1_121_940, 1_568_626, 1_708_126_208), (8_973_782, 12_485_338, 12_718_411_776))
#: Bytes per element the result keeps (cells, material, a flux per axis).
BYTES_PER_CELL = {2: 60.0, 3: 100.0}
#: Reading a size: K, M, G, T (powers of 1024).
_SCALE = {"k": 2 ** 10, "m": 2 ** 20, "g": 2 ** 30, "t": 2 ** 40}


def parse_memory(text: str) -> float:
    """``--memory``: a size in bytes with an optional K, M, G or T suffix (``4G``).

    >>> parse_memory("1.5G") == 3 * 2 ** 29
    True
    """
    t = str(text).strip().lower().removesuffix("ib").removesuffix("b")
    scale = _SCALE.get(t[-1:], 1)
    try:
        value = float(t[:-1] if scale > 1 else t) * scale
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise ValueError(f"--memory takes a size such as 4G or 500M, not {text!r}.")
    return value


def unknowns(mesh: Mesh, order: int) -> int:
    """Degrees of freedom of a P1/P2 solve on `mesh` (P2: vertices + edges, by Euler)."""
    n = len(mesh.points)
    return n if order == 1 else n + n + mesh.n_cells


def estimate_memory(mesh: Mesh, order: int, interval: bool, periodic: bool = False) -> int:
    """Estimated peak bytes of a steady run on `mesh`.

    Parameters
    ----------
    mesh : Mesh
    order : {1, 2}
    interval : bool
        With the dual solve of the certified interval (it runs after the primal one, so
        the larger of the two counts, plus the primal potential kept for the gap).
    periodic : bool
        The periodic protocol (P2 assembled in full) instead of the mixed one (P2 in
        half storage).

    Examples
    --------
    >>> import numpy as np
    >>> from napari_swa_imesh.mesh import mesh_labels
    >>> estimate_memory(mesh_labels(np.ones((4, 4), np.uint8)), 1, False) > 0
    True
    """
    d = mesh.ndim
    half = order == 2 and not periodic
    primal = (BYTES_PER_UNKNOWN_HALF[d] * unknowns(mesh, order) + BYTES_HALF_FIXED if half
              else BYTES_PER_UNKNOWN[(d, order)] * unknowns(mesh, order))
    peak = primal
    if interval:
        facets = (d + 1) * mesh.n_cells / 2
        peak = max(primal, BYTES_PER_FACET[d] * facets + 8 * unknowns(mesh, order))
    return int(peak + BYTES_PER_CELL[d] * mesh.n_cells)


def format_bytes(n: float) -> str:
    """``1.5 GB``, ``320 MB``: binary units, three figures."""
    for unit, size in (("GB", 2 ** 30), ("MB", 2 ** 20), ("kB", 2 ** 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} B"


def check_memory(mesh: Mesh, order: int, interval: bool, memory: float, *,
                 asked: bool, periodic: bool = False) -> str | None:
    """None when a run on `mesh` fits `memory` bytes; else why not.

    With `asked` (the run the caller asked for) a run that does not fit is refused with a
    ValueError that says what to do; otherwise (a refinement the run would like) the
    reason is returned as a clause for the warning. `periodic` as for
    :func:`estimate_memory`.
    """
    need = estimate_memory(mesh, order, interval, periodic=periodic)
    if need <= memory:
        return None
    if asked:
        raise ValueError(
            f"P{order} on {mesh.n_cells:,} elements needs about {format_bytes(need)}, above "
            f"the memory budget of {format_bytes(memory)}: pass a larger --memory"
            + (", --order 1" if order == 2 else "")
            + (" or --no-interval (skips the dual solve)" if interval else "")
            + ", or crop the image.")
    return (f"the next refinement would need about {format_bytes(need)}, above the memory "
            f"budget of {format_bytes(memory)} (raise it with --memory)")


def fit_interval(mesh: Mesh, order: int, interval: bool, memory: float,
                 note: str | None = None) -> tuple[bool, str | None]:
    """Whether the interval's dual solve still fits `memory`, and the note when it does not.

    A run whose conforming solve fits but whose dual does not goes on without the interval
    (k_eff is then the conforming, upper estimate alone) and says so, instead of refusing
    a default run at 128^3 for a certificate the user did not ask for by name. `note`
    (an earlier step's) is passed through.

    Examples
    --------
    >>> import numpy as np
    >>> from napari_swa_imesh.mesh import mesh_labels
    >>> mesh = mesh_labels(np.indices((6, 6, 6)).sum(0) % 2 + 1)   # 3-D: the dual outweighs P1
    >>> fit_interval(mesh, 1, True, 4 * 2 ** 30)
    (True, None)
    >>> keep, note = fit_interval(mesh, 1, True, estimate_memory(mesh, 1, False))
    >>> keep, note.startswith("no certified interval")
    (False, True)
    """
    if (not interval or estimate_memory(mesh, order, True) <= memory
            or estimate_memory(mesh, order, False) > memory):
        return interval, note
    return False, (f"no certified interval: its dual solve would need about "
                   f"{format_bytes(estimate_memory(mesh, order, True))}, above the memory "
                   f"budget of {format_bytes(memory)}, so k_eff is the conforming (upper) "
                   "estimate alone; raise --memory for the interval.")
