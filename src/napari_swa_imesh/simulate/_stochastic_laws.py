"""The laws of the stochastic step: the property map and each material's intensity statistics.

A material is random when the signatures give it ``mean_mean`` and ``mean_std`` (from at
least two tiles) and fixed when a conductivity is given for it (by label or by the
signatures' name); :func:`material_laws` checks them from the label set, before meshing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from ..mesh import Mesh
from ._conductivity import conductivity_tensors, material_label
from ._report import match_signatures, read_signatures

__all__ = ["MAPS", "MEAN", "STD", "PropertyMap", "fixed_tensors", "material_laws",
           "parse_property_map", "signature_tile_size"]

MAPS = ("log-linear",)
MEAN, STD = "mean_mean", "mean_std"     # the signature columns used


@dataclass(frozen=True)
class PropertyMap:
    """A map from intensity to conductivity: ``log k = a + b * intensity`` (log-linear).

    Attributes
    ----------
    kind : str
        ``"log-linear"``.
    a, b : float
        Intercept and slope of ``log k``.
    """

    kind: str
    a: float
    b: float

    def log_moments(self, mean: float, std: float) -> tuple[float, float]:
        """Mean and standard deviation of ``log k`` for an intensity of `mean` and `std`."""
        return self.a + self.b * mean, abs(self.b) * std

    def __str__(self) -> str:
        return f"{self.kind}:{self.a:g},{self.b:g}"


def parse_property_map(text) -> PropertyMap:
    """A :class:`PropertyMap` from its text, ``"log-linear:a,b"``.

    Parameters
    ----------
    text : str or PropertyMap

    Returns
    -------
    PropertyMap

    Examples
    --------
    >>> parse_property_map("log-linear:0,0.5").b
    0.5
    """
    if isinstance(text, PropertyMap):
        return text
    kind, _, numbers = str(text).partition(":")
    try:
        a, b = (float(v) for v in numbers.split(","))
    except ValueError:
        a = b = float("nan")
    if kind not in MAPS or not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError(f"the property map must be log-linear:a,b (log k = a + b * "
                         f"intensity, two finite numbers such as log-linear:0,0.01), not "
                         f"{text!r}.")
    return PropertyMap(kind, a, b)


def signature_tile_size(signatures) -> float | None:
    """The RES tile side, ``2**scale`` voxels, from the signatures' ``scale`` column.

    Parameters
    ----------
    signatures : sequence of mapping
        Rows as :func:`~._report.read_signatures` returns them.

    Returns
    -------
    float or None
        None when no row has a scale (an older or hand-made table).

    Raises
    ------
    ValueError
        Rows at different scales, or a scale that is not a whole number of 0 or more.

    Examples
    --------
    >>> signature_tile_size([{"label": 1, "scale": 3}, {"label": 2, "scale": 3}])
    8.0
    """
    scales = {row.get("scale") for row in signatures} - {None}
    scales = {v for v in scales if not (isinstance(v, float) and math.isnan(v))}
    if not scales:
        return None
    bad = [v for v in scales if not isinstance(v, Integral) or v < 0]
    if bad or len(scales) > 1:
        raise ValueError(f"the signatures' scale column holds {sorted(map(str, scales))}, "
                         "not one whole number: give the RES tile side with --tile-size.")
    return float(2 ** int(next(iter(scales))))


def material_laws(signatures, present: list[int], mesh_names: Mapping[int, str], conductivity,
          prop: PropertyMap, ndim: int) -> tuple:
    """Per material of `present`: random ``(label, log mean, log std)`` or fixed.

    Returns the random laws, the fixed labels with their (n, d, d) tensors, and the rows
    of the result's material table; checked from the labels before any meshing.
    """
    if isinstance(signatures, (str, Path)):
        signatures = read_signatures(signatures)
    by_label, _ = match_signatures(signatures, mesh_names)
    conductivity = dict(conductivity or {})
    # the signatures' names serve `conductivity` too (they agree with the mesh's)
    names = {**{k: str(r["name"]) for k, r in by_label.items() if r.get("name")},
             **mesh_names}
    chosen = {material_label(k, names): k for k in conductivity}
    unknown = [k for label, k in chosen.items() if label not in present]
    if unknown:
        raise ValueError(f"the fixed conductivity names material {unknown[0]!r}, which is "
                         f"not meshed (materials {', '.join(map(str, present))}); give a "
                         "meshed label or a name from the signatures.")
    random, fixed, rows = [], [], {}
    for label in present:
        row = by_label.get(label)
        if label in chosen:
            fixed.append(label)
            continue
        what = f"material {label}" + (f" ({names[label]})" if names.get(label) else "")
        if row is None:
            raise ValueError(f"{what} has no row in the signatures; give it a fixed "
                             f"conductivity (--conductivity {label}=K) or use the "
                             "signatures of these labels.")
        mean, std = row.get(MEAN), row.get(STD)
        mean = float(mean) if isinstance(mean, Real) else math.nan
        std = float(std) if isinstance(std, Real) else math.nan
        if not (math.isfinite(mean) and math.isfinite(std) and std >= 0):
            raise ValueError(f"{what} has no finite {MEAN} and {STD} in the signatures "
                             f"(got {row.get(MEAN)!r}, {row.get(STD)!r}: no full tile "
                             "was classified as it?); "
                             f"give it a fixed conductivity (--conductivity {label}=K).")
        tiles = row.get("tiles")
        if isinstance(tiles, Real) and tiles < 2:
            raise ValueError(f"{what} has {tiles:g} tile in the signatures, too few for a "
                             f"standard deviation; give it a fixed conductivity "
                             f"(--conductivity {label}=K) or segment at a finer scale.")
        log_mean, log_std = prop.log_moments(mean, std)
        random.append((int(label), log_mean, log_std))
        rows[int(label)] = {"name": names.get(label, str(row.get("name") or "")),
                            "intensity_mean": mean, "intensity_std": std,
                            "log_k_mean": log_mean, "log_k_std": log_std}
    table = conductivity_tensors(conductivity, fixed, ndim, names) if fixed else None
    return tuple(random), fixed, table, rows


def fixed_tensors(mesh: Mesh, fixed: list[int], table) -> np.ndarray:
    """(M, d, d) the fixed materials' tensors per element, zero elsewhere."""
    tensors = np.zeros((mesh.n_cells, mesh.ndim, mesh.ndim))
    if fixed:
        where = np.searchsorted(fixed, mesh.material)
        held = np.isin(mesh.material, fixed)
        tensors[held] = table[where[held]]
    return tensors
