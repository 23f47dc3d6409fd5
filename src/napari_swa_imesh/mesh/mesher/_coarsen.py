"""Coarser labels for large smooth volumes: every 2^K block takes its majority label.

Meshing the coarsened labels gives leaves of at least 2^K voxels everywhere (except where
the image ends inside a block), so a large volume whose materials are much thicker than
a voxel meshes with far fewer elements. The price is exactness: material boundaries move
to the 2^K grid, and the per-material volume change is reported, never hidden.
"""

from __future__ import annotations

import numpy as np

from ..._region_tree import pad_to_multiple

__all__ = ["MAX_COARSEN", "coarsen_labels"]

#: Largest coarsening level (blocks of 2^5 = 32 voxels per axis).
MAX_COARSEN = 5


def check_coarsen(coarsen) -> int:
    """`coarsen` as an int in ``0 .. MAX_COARSEN``, or ValueError saying what to pass."""
    from ._lattice import check_level

    return check_level(coarsen, "coarsen", MAX_COARSEN,
                       "labels are meshed in blocks of 2^coarsen voxels")


def coarsen_labels(lab: np.ndarray, level: int, exclude=()) -> tuple[np.ndarray, dict]:
    """Replace every block of ``2**level`` voxels per axis by its majority label.

    Parameters
    ----------
    lab : ndarray of int
        Checked label image (2-D or 3-D).
    level : int
        Block side ``2**level``; 0 returns `lab` itself.
    exclude : sequence of int
        Labels that will not be meshed: coarsened labels holding nothing else are
        refused (ValueError), since nothing would be left to mesh.

    Returns
    -------
    labels : ndarray
        Same shape and dtype as `lab`. Blocks cut by the image's far end vote with the
        voxels they hold; ties go to the lowest label.
    report : dict
        ``voxels_before`` and ``voxels_after`` per material (label -> count),
        ``relative_change`` per material (after / before - 1), ``lost`` (materials no
        block keeps) and ``changed_voxels``.

    Examples
    --------
    >>> lab = np.array([[1, 1, 2, 2], [1, 2, 2, 2]])
    >>> coarsen_labels(lab, 1)[0].tolist()
    [[1, 1, 2, 2], [1, 1, 2, 2]]
    """
    if level == 0:
        values, counts = np.unique(lab, return_counts=True)
        before = {int(v): int(c) for v, c in zip(values, counts)}
        return lab, {"level": 0, "voxels_before": before, "voxels_after": dict(before),
                     "relative_change": {v: 0.0 for v in before}, "lost": [],
                     "changed_voxels": 0}
    d = lab.ndim
    side = 1 << level
    top = int(lab.max()) if lab.size else 0
    # the padding value must sort after every label and fit the dtype
    dtype = lab.dtype if top < np.iinfo(lab.dtype).max else np.dtype(np.int64)
    padded = pad_to_multiple(lab.astype(dtype, copy=False), side, top + 1)
    coarse_shape = tuple(n // side for n in padded.shape)
    pairs = sum(((c, side) for c in coarse_shape), ())
    order = tuple(range(0, 2 * d, 2)) + tuple(range(1, 2 * d, 2))
    rows = padded.reshape(pairs).transpose(order).reshape(-1, side ** d)
    rows = np.sort(rows, axis=1)
    # length of the run of equal values ending at each position of a sorted row
    position = np.arange(rows.shape[1])
    start = np.zeros(rows.shape, dtype=np.int32)
    start[:, 1:] = np.where(rows[:, 1:] != rows[:, :-1], position[1:], 0)
    np.maximum.accumulate(start, axis=1, out=start)
    run = position[None, :] - start + 1
    run[rows == top + 1] = 0                                   # padding does not vote
    # the longest run wins; argmax takes the first, i.e. the lowest label on a tie
    winner = rows[np.arange(len(rows)), np.argmax(run, axis=1)]
    del rows, start, run
    coarse = winner.reshape(coarse_shape).astype(lab.dtype, copy=False)
    out = coarse
    for axis in range(d):
        out = np.repeat(out, side, axis=axis)
    out = np.ascontiguousarray(out[tuple(slice(0, n) for n in lab.shape)])

    values, counts = np.unique(lab, return_counts=True)
    before = {int(v): int(c) for v, c in zip(values, counts)}
    values, counts = np.unique(out, return_counts=True)
    after = {int(v): int(c) for v, c in zip(values, counts)}
    excluded = {int(v) for v in np.asarray(exclude, dtype=np.int64).ravel()}
    if excluded and set(after) <= excluded:
        kept = sorted(set(before) - excluded)
        raise ValueError(
            f"coarsening to blocks of {side} voxels per axis leaves only excluded labels "
            f"({sorted(after)}): no block has a majority of the materials to mesh "
            f"({kept}); use a lower --coarsen level, or exclude fewer materials.")
    return out, {
        "level": int(level),
        "voxels_before": before,
        "voxels_after": {v: after.get(v, 0) for v in before},
        "relative_change": {v: after.get(v, 0) / c - 1.0 for v, c in before.items()},
        "lost": [v for v in before if v not in after],
        "changed_voxels": int(np.count_nonzero(out != lab)),
    }
