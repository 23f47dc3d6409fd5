"""Material signatures (reference Table 2.13): per material, the mean and standard deviation
of each tile moment over the tiles classified as it, and their CSV file."""

from __future__ import annotations

import csv
import io as _io
from pathlib import Path

import numpy as np

from ..io import atomic_write
from ._moments import MOMENT_NAMES

__all__ = ["material_signatures", "signatures_csv_text", "write_signatures_csv"]


def material_signatures(moments: np.ndarray, counts: np.ndarray, tile_labels: np.ndarray,
                        materials) -> list[dict]:
    """Per material: mean and std of each moment over the full tiles classified as it.

    Parameters
    ----------
    moments : (t_0, ..., t_{d-1}, 4) ndarray of float64
        Tile moments (:func:`~._moments.tile_moments`).
    counts : (t_0, ..., t_{d-1}) ndarray of int
        Pixels per tile; only full tiles count.
    tile_labels : (t_0, ..., t_{d-1}) ndarray of int
    materials : sequence of Material

    Returns
    -------
    list of dict
        One row per material: ``label``, ``name``, ``tiles``, then ``{moment}_mean`` and
        ``{moment}_std`` (NaN for a material no full tile was classified as).
    """
    full = counts == counts.max()
    rows = []
    for m in materials:
        sel = full & (tile_labels == m.label)
        tiles = moments[sel]
        row = {"label": m.label, "name": m.name, "tiles": int(sel.sum())}
        for k, name in enumerate(MOMENT_NAMES):
            row[f"{name}_mean"] = float(tiles[:, k].mean()) if tiles.size else float("nan")
            row[f"{name}_std"] = float(tiles[:, k].std()) if tiles.size else float("nan")
        rows.append(row)
    return rows


def signatures_csv_text(signatures: list[dict]) -> str:
    """The material-signature table (one row per material) as CSV text."""
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(signatures[0]))
    writer.writeheader()
    writer.writerows(signatures)
    return buf.getvalue()


def write_signatures_csv(signatures: list[dict], path, *, force: bool = False) -> Path:
    """Write the material-signature table (one row per material) as CSV.

    Parameters
    ----------
    signatures : list of dict
        Per material, as :attr:`SegmentationResult.signatures` holds them.
    path : str or Path
        The CSV file (written atomically).
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        `path`.
    """
    with atomic_write([path], force=force) as (tmp,):
        tmp.write_text(signatures_csv_text(signatures))
    return Path(path)
