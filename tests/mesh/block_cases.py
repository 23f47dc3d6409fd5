"""Seeded volumes, the tasks' grids in memory and a broken block shared by the block-wise
meshing tests (not a test module)."""

from __future__ import annotations

import numpy as np

from napari_swa_imesh.mesh.blocks import _core as bk


def boxed(shape, seed: int, p: float) -> np.ndarray:
    """Material 1 with a box of 2 inside, isolated pixels of 3 (a fraction `p`) and a
    corner of excluded 0: interfaces in every block, fine next to coarse."""
    rng = np.random.default_rng(seed)
    lab = np.ones(shape, np.int64)
    lab[tuple(slice(n // 4, n - n // 3) for n in shape)] = 2
    lab[rng.random(shape) < p] = 3
    lab[(slice(0, 2),) * len(shape)] = 0
    return lab


def balanced_grids(lab, block: int, exclude=(0,), *, periodic: bool = False):
    """What the tasks compute before meshing, in memory (no files): the plan, each block's
    mixed grids, the grids balanced across the blocks, and the materials to mesh."""
    plan = bk.plan_blocks(lab.shape, block, periodic=periodic)
    mixed = {}
    for idx in plan.blocks():
        sl, _ = plan.window(idx)
        mixed[idx] = bk.mixed_grids(bk._window_labels(plan, idx, lab[sl]), plan.top)
    present = sorted(set(np.unique(lab).tolist()) - set(exclude))
    return plan, mixed, bk.balance_grids(plan, mixed), present


def misalign_block(monkeypatch, index: tuple[int, ...]) -> None:
    """Make the block at `index` come back with its vertices and seams one lattice key
    off (through ``monkeypatch``, undone after the test): the seam check must catch it."""
    real = bk.mesh_block

    def shifted(plan, idx, *args, **kw):
        piece = real(plan, idx, *args, **kw)
        if idx == index:
            piece.gid = piece.gid + 1
            piece.seams = {k: v + 1 for k, v in piece.seams.items()}
        return piece

    monkeypatch.setattr(bk, "mesh_block", shifted)
