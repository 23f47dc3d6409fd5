"""Realistic brain MR phantoms from real adult anatomy, for the segmentation benchmarks.

Anatomy: the ICBM 2009a symmetric MNI152 template's grey- and white-matter probability maps
and brain mask (1 mm), bundled with nilearn (no network). CSF is the rest of the brain mask,
``1 - GM - WM``; ventricles and sulci are where both maps are low.

A *case* is one crop of one anatomy at one noise and bias level:

* **anatomies**: the template warped by a smooth random displacement field (about 3 mm,
  correlation length ~2 cm), one field per anatomy seed, so the folds differ;
* **crops**: four quadrants of the brain (anterior/posterior x inferior/superior, 64 x 96 x
  144 voxels, (plane, row, column) = (inferior->superior, posterior->anterior... as stored)).
  The development split uses two diagonal quadrants, the held-out validation split the other
  two, with other anatomy and noise seeds: no voxel of a validation crop is in a dev crop;
* **image**: partial-volume T1 intensities ``sum_k p_k mu_k`` (background 0, CSF 0.25, GM
  0.55, WM 0.80 as :func:`napari_swa_imesh.data.tissue_phantom`), a smooth multiplicative
  bias of amplitude 0 % or 40 % (the same field model as ``tissue_phantom``), Rician
  magnitude noise of sigma 3 % or 9 % of the white-matter intensity (BrainWeb's convention);
* **truth**: the most probable tissue inside the brain mask (1 CSF, 2 GM, 3 WM), 0 outside;
  Dice is measured inside the brain mask only (:func:`brain_dice`).

Sample boxes come from the truth exactly as ``swa-imesh samples-from-truth --scale 2`` makes
them (:func:`samples_for`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import ndimage as ndi

__all__ = ["TISSUES", "MEANS", "INVERTED", "VARIANTS", "SPLITS", "cases", "make_case",
           "samples_for", "brain_dice"]

TISSUES = {1: "CSF", 2: "GM", 3: "WM"}
MEANS = np.array([0.0, 0.25, 0.55, 0.80], np.float32)      # background, CSF, GM, WM
# the tissues' order reversed (CSF brightest, as in T2) on the same dark background, for
# checking a contrast-order fix on the tuning generator (make_case(..., means=INVERTED))
INVERTED = np.array([0.0, 0.80, 0.55, 0.25], np.float32)
VARIANTS = [(0.03, 0.0), (0.03, 0.4), (0.09, 0.0), (0.09, 0.4)]    # (noise, bias)
CROP = (64, 96, 144)            # (z, y, x) voxels of a quadrant
# quadrant origins in the template's (z, y, x) voxel grid (z up, y anterior)
_QUADRANTS = {"inf-post": (16, 20, 26), "inf-ant": (16, 116, 26),
              "sup-post": (80, 20, 26), "sup-ant": (80, 116, 26)}
# split -> list of (crop, anatomy seed, noise seeds); validation is never tuned on
SPLITS = {
    "dev": [("inf-post", 1, (11, 12)), ("sup-ant", 2, (21, 22))],
    "val": [("inf-ant", 3, (31, 32)), ("sup-post", 4, (41, 42))],
}
WARP_MM = 3.0
WARP_CORR_MM = 20.0


@lru_cache(maxsize=1)
def template() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(gm, wm, brain) float32 maps in (z, y, x) order, 1 mm (nilearn's bundled MNI152)."""
    from nilearn import datasets

    def arr(img):
        return np.ascontiguousarray(np.asarray(img.dataobj, np.float32).transpose(2, 1, 0))

    gm = arr(datasets.load_mni152_gm_template(resolution=1))
    wm = arr(datasets.load_mni152_wm_template(resolution=1))
    brain = arr(datasets.load_mni152_brain_mask(resolution=1))
    # a soft mask edge: the brain's outer voxels are partly background
    brain = np.clip(ndi.gaussian_filter(brain, 0.5), 0, 1)
    return gm, wm, brain


def _displacement(shape, rng) -> list[np.ndarray]:
    """Smooth random displacement (voxels) per axis, peak about :data:`WARP_MM`."""
    out = []
    for _ in shape:
        small = tuple(max(2, int(np.ceil(n / 8))) for n in shape)
        f = ndi.gaussian_filter(rng.standard_normal(small), WARP_CORR_MM / 8, mode="wrap")
        f = ndi.zoom(f, [n / s for n, s in zip(shape, small)], order=1)[
            tuple(slice(0, n) for n in shape)]
        out.append((WARP_MM * f / (np.abs(f).max() + 1e-12)).astype(np.float32))
    return out


def anatomy_crop(crop: str, anatomy: int) -> tuple[np.ndarray, np.ndarray]:
    """Tissue probabilities (4, z, y, x) [background, CSF, GM, WM] of a warped crop, and
    the brain mask (bool) of the truth."""
    gm, wm, brain = template()
    origin = _QUADRANTS[crop]
    rng = np.random.default_rng(1000 + anatomy)
    grid = np.meshgrid(*[np.arange(o, o + n, dtype=np.float32) for o, n in
                         zip(origin, CROP)], indexing="ij")
    coords = [g + d for g, d in zip(grid, _displacement(CROP, rng))]
    gm_c, wm_c, br_c = (ndi.map_coordinates(m, coords, order=1, mode="nearest")
                        for m in (gm, wm, brain))
    tissue = np.clip(gm_c + wm_c, 0, 1)
    scale = np.where(gm_c + wm_c > 1, 1 / np.maximum(gm_c + wm_c, 1e-6), 1.0)
    gm_c, wm_c = gm_c * scale, wm_c * scale
    # inside the brain, what is not GM or WM is CSF; the soft edge is background
    csf = br_c * (1 - tissue)
    prob = np.stack([1 - br_c, csf, br_c * gm_c, br_c * wm_c]).astype(np.float32)
    return prob, br_c >= 0.5


def make_case(crop: str, anatomy: int, noise: float, bias: float, seed: int,
              means: np.ndarray = MEANS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(image float32, truth int32, brain bool) of one case (see the module docstring);
    `means`: background, CSF, GM and WM intensities (:data:`INVERTED`: CSF brightest)."""
    from napari_swa_imesh.data import _smooth_field

    prob, brain = anatomy_crop(crop, anatomy)
    truth = np.where(brain, np.argmax(prob[1:], axis=0) + 1, 0).astype(np.int32)
    clean = np.tensordot(np.asarray(means, np.float32), prob, axes=1)
    rng = np.random.default_rng(seed)
    if bias:
        field = _smooth_field(CROP, rng, 0.5)
        ramp = np.linspace(-1, 1, CROP[0]).reshape(-1, 1, 1)
        clean = clean * (1 + bias / 2 * np.clip(0.5 * field + 0.5 * ramp, -1, 1))
    sigma = noise * MEANS[3]
    image = np.hypot(clean + sigma * rng.standard_normal(CROP),
                     sigma * rng.standard_normal(CROP))
    return image.astype(np.float32), truth, brain


def cases(split: str, variants=VARIANTS):
    """Yield ``(name, (noise, bias), image, truth, brain)`` for every case of a split."""
    for noise, bias in variants:
        for crop, anatomy, seeds in SPLITS[split]:
            for seed in seeds:
                image, truth, brain = make_case(crop, anatomy, noise, bias, seed)
                yield f"{crop}/a{anatomy}/s{seed}", (noise, bias), image, truth, brain


def samples_for(truth):
    """Sample boxes as ``swa-imesh samples-from-truth --scale 2`` makes them."""
    from napari_swa_imesh.segmentation import samples_from_truth

    return samples_from_truth(truth, scale=2, per_material=4, names=dict(TISSUES))


def brain_dice(labels, truth, brain) -> dict[int, float]:
    """Dice per tissue inside the brain mask."""
    from napari_swa_imesh.segmentation import dice_scores

    return dice_scores(np.where(brain, labels, 0), truth, materials=list(TISSUES))
