"""Feature sets F1..F7 (reference Table 2.1): per-tile feature stacks, channel-last.

Groups: ``"M"`` moments (4: mean, variance, skewness, Pearson kurtosis, see
:mod:`._moments`), ``"H"`` wavelet entropies (``(2**d - 1) * scale + 1``, see
:mod:`._entropy`), ``"Z"`` correlation lengths (``d``, see :mod:`._correlation`;
needs ``scale >= 2``). Within a stack the groups come in the order of the set's
name, e.g. F5 = (H, M): entropies first, then moments.
"""

from __future__ import annotations

import numpy as np

from napari_swa_imesh._validation import as_image

from ._correlation import tile_correlation_worker
from ._entropy import entropy_feature_names, tile_entropy_worker
from ._moments import MOMENT_NAMES, tile_moments_worker
from ._tiles import tile_counts, validate_mask, validate_scale

__all__ = ["FEATURE_SETS", "feature_names", "feature_stack", "n_features"]

FEATURE_SETS: dict[str, tuple[str, ...]] = {
    "F1": ("M",),
    "F2": ("H",),
    "F3": ("Z",),
    "F4": ("M", "Z"),
    "F5": ("H", "M"),
    "F6": ("H", "Z"),
    "F7": ("H", "M", "Z"),
}


def _normalize_feature_set(feature_set) -> str:
    """Return the canonical key ("F1".."F7") of `feature_set` (case-insensitive)."""
    if not isinstance(feature_set, str):
        raise TypeError(
            f"feature_set must be a string such as 'F1'; got {feature_set!r} of type "
            f"{type(feature_set).__name__}."
        )
    key = feature_set.strip().upper()
    if key not in FEATURE_SETS:
        valid = ", ".join(f"{name} {'+'.join(groups)}" for name, groups in FEATURE_SETS.items())
        raise ValueError(
            f"unknown feature set {feature_set!r}; valid ones (case-insensitive) are: {valid}."
        )
    return key


def _group_names(group: str, ndim: int, scale: int) -> list[str]:
    if group == "M":
        return list(MOMENT_NAMES)
    if group == "H":
        return entropy_feature_names(ndim, scale)
    return [f"corr_length_axis{axis}" for axis in range(ndim)]


def feature_names(feature_set: str, ndim: int, scale: int) -> list[str]:
    """Names of the features of `feature_set`, in stack order.

    Examples
    --------
    >>> feature_names("f4", 2, 3)
    ['mean', 'variance', 'skewness', 'kurtosis', 'corr_length_axis0', 'corr_length_axis1']
    """
    key = _normalize_feature_set(feature_set)
    return [name for group in FEATURE_SETS[key] for name in _group_names(group, ndim, scale)]


def n_features(feature_set: str, ndim: int, scale: int) -> int:
    """Number of features of `feature_set` for a `ndim`-D image at `scale`.

    M gives 4, H gives ``(2**ndim - 1) * scale + 1``, Z gives ``ndim``.

    Parameters
    ----------
    feature_set : str
        One of :data:`FEATURE_SETS` (``"F1"`` .. ``"F7"``).
    ndim : int
        Image dimensionality.
    scale : int
        Tile scale j.

    Returns
    -------
    int
        The length of a tile's feature vector.

    Examples
    --------
    >>> n_features("F2", 2, 3), n_features("F7", 3, 2)
    (10, 22)
    """
    return len(feature_names(feature_set, ndim, scale))


def feature_stack(
    image, scale: int, feature_set: str = "F1", *, mask=None
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per-tile features of one feature set, channel-last.

    Parameters
    ----------
    image : (N_0, ..., N_{d-1}) array_like of real numbers
        Grey-level image, 2-D or more, any real dtype (computed in float64). Not
        modified.
    scale : int
        Tiles of ``2**scale`` pixels per axis, ``0 .. floor(log2(max side))``
        (at least 2 for sets with Z: F3, F4, F6, F7).
    feature_set : str
        "F1" .. "F7" (case-insensitive), see :data:`FEATURE_SETS`.
    mask : (N_0, ..., N_{d-1}) array_like of bool, optional
        True where a pixel counts (see each group for how masked pixels are
        treated).

    Returns
    -------
    features : (t_0, ..., t_{d-1}, n_features) ndarray of float64
        ``t_a = ceil(N_a / 2**scale)``; NaN for tiles with no valid pixel.
    counts : (t_0, ..., t_{d-1}) ndarray of int64
        Valid pixels per tile; ``2**(scale * d)`` for full tiles (partial edge
        tiles and masked tiles have fewer).
    names : list of str
        Feature names, see :func:`feature_names`.

    Examples
    --------
    >>> features, counts, names = feature_stack(np.arange(16.0).reshape(4, 4), 1, "F1")
    >>> features.shape, counts.tolist(), names[:2]
    ((2, 2, 4), [[4, 4], [4, 4]], ['mean', 'variance'])
    >>> features[0, 0, :2].tolist()  # pixels 0, 1, 4, 5
    [2.5, 4.25]
    """
    x = as_image(image)
    valid = validate_mask(mask, x.shape)
    scale = validate_scale(scale, x.shape)
    key = _normalize_feature_set(feature_set)
    groups = FEATURE_SETS[key]
    if "Z" in groups and scale < 2:
        raise ValueError(
            f"feature set {key} contains correlation lengths (Z), which need scale >= 2 "
            f"(tiles of 4 or more pixels per axis); got scale={scale}. Use a larger scale "
            "or F1, F2 or F5."
        )
    parts: dict[str, np.ndarray] = {}
    if "H" in groups:
        parts["H"] = tile_entropy_worker(x, valid, scale)
    if "Z" in groups:
        parts["Z"] = tile_correlation_worker(x, valid, scale)
    if "M" in groups:
        parts["M"], counts = tile_moments_worker(x, valid, scale)
    else:
        counts = tile_counts(x.shape, scale, valid)
    features = np.concatenate([parts[group] for group in groups], axis=-1)
    return features, counts, feature_names(key, x.ndim, scale)
