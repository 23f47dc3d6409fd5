"""A second, independent MR phantom generator: the held-out one nothing is tuned on.

:mod:`anatomy` (the *tuning* generator) turns the MNI152 probability maps into intensities
by tissue-probability mixing, Rician noise and a random-Gaussian bias field at 1 mm. This
one shares only the anatomy source and differs in every step from anatomy to intensity:

* **labels, then a PSF**: each voxel of a 0.5 mm grid takes its most probable tissue (hard
  labels, sharper sulci than the maps' average), the T1 contrast of that label, and the
  scanner's point-spread function (Gaussian, FWHM one output voxel per axis) and the
  averaging over the output voxel make the partial volume;
* **other contrast ratios** (CSF 0.20, GM 0.62, WM 0.86 against 0.25 / 0.55 / 0.80), and a
  within-tissue intensity texture (smooth, 3 %) that no class mean describes;
* **Gaussian noise** (a magnitude image of high SNR; sigma 3 % or 9 % of WM), not Rician;
* **bias**: a random low-order field, ``exp`` of a cubic polynomial of the physical
  coordinates scaled to a peak-to-peak of 0 % or 40 %;
* **voxels**: 1 mm isotropic, and 1.5 x 0.94 x 0.94 mm (plane, row, column).

Crops are the held-out quadrants of :mod:`anatomy` (``inf-ant``, ``sup-post``) with
anatomy seeds of their own; the truth is the most probable tissue of the output voxel
(the fraction of the 0.5 mm labels inside it), Dice inside the brain as :mod:`anatomy`.
"""

from __future__ import annotations

try:                    # imported as benchmarks.anatomy_heldout (the tests)
    from . import anatomy
except ImportError:     # a script's neighbour (python benchmarks/bench_accuracy.py)
    import anatomy
import numpy as np
from scipy import ndimage as ndi

__all__ = ["CASES", "CROP_MM", "MEANS", "VARIANTS", "cases", "make_case"]

MEANS = np.array([0.0, 0.20, 0.62, 0.86], np.float32)       # background, CSF, GM, WM
# (noise, bias, spacing): 1 mm and 1.5 x 0.94 x 0.94 mm voxels
VARIANTS = [(0.03, 0.0, (1.0, 1.0, 1.0)), (0.03, 0.4, (1.0, 1.0, 1.0)),
            (0.09, 0.0, (1.0, 1.0, 1.0)), (0.09, 0.4, (1.0, 1.0, 1.0)),
            (0.03, 0.0, (1.5, 0.94, 0.94)), (0.03, 0.4, (1.5, 0.94, 0.94))]
CROP_MM = (48.0, 72.0, 108.0)   # physical extent of a crop (z, y, x), inside a quadrant
# (quadrant, anatomy seed, noise seed); the held-out quadrants of the tuning generator
CASES = [("inf-ant", 7, 71), ("sup-post", 8, 81)]
TEXTURE = 0.03
FINE = 0.5                      # mm of the hard-label grid


def _fine_labels(crop: str, anatomy_seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Hard labels (0 bg, 1 CSF, 2 GM, 3 WM) on the 0.5 mm grid of a warped crop, and the
    0.5 mm grid's physical origin offset (mm)."""
    gm, wm, brain = anatomy.template()
    origin = np.array(anatomy._QUADRANTS[crop], float) + 4.0
    rng = np.random.default_rng(5000 + anatomy_seed)
    n = [round(e / FINE) for e in CROP_MM]
    axes = [o + (np.arange(k) + 0.5) * FINE - 0.5 for o, k in zip(origin, n)]
    grid = np.meshgrid(*[a.astype(np.float32) for a in axes], indexing="ij")
    disp = anatomy._displacement(tuple(max(2, k // 2) for k in n), rng)
    disp = [ndi.zoom(d, [k / s for k, s in zip(n, d.shape)], order=1)[
        tuple(slice(0, k) for k in n)] for d in disp]
    coords = [g + d for g, d in zip(grid, disp)]
    gm_c, wm_c, br_c = (ndi.map_coordinates(m, coords, order=1, mode="nearest")
                        for m in (gm, wm, brain))
    csf = np.clip(1 - gm_c - wm_c, 0, 1)
    lab = np.argmax(np.stack([csf, gm_c, wm_c]), axis=0).astype(np.int8) + 1
    return np.where(br_c >= 0.5, lab, 0).astype(np.int8), np.asarray(n)


def _poly_field(shape, spacing, amplitude, rng) -> np.ndarray:
    """exp of a random cubic polynomial of the coordinates, peak-to-peak `amplitude`."""
    coords = np.meshgrid(*[np.linspace(-1, 1, k) for k in shape], indexing="ij")
    log = np.zeros(shape)
    for i in range(4):
        for j in range(4 - i):
            for k in range(4 - i - j):
                if i + j + k:
                    log += rng.normal() / (i + j + k) * coords[0] ** i * coords[1] ** j \
                        * coords[2] ** k
    log = (log - log.min()) / max(np.ptp(log), 1e-12)          # 0..1
    return np.exp(np.log1p(amplitude) * (log - 0.5))


def make_case(crop: str, anatomy_seed: int, noise: float, bias: float, spacing, seed: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(image float32, truth int32, brain bool) of one held-out case."""
    lab, n = _fine_labels(crop, anatomy_seed)
    rng = np.random.default_rng(seed)
    # T1 of the labels with a smooth within-tissue texture, then the PSF and the voxel
    tex = ndi.gaussian_filter(rng.standard_normal(tuple(k // 4 for k in n)), 2.0)
    tex = ndi.zoom(tex / (tex.std() + 1e-12), [k / s for k, s in zip(n, tex.shape)],
                   order=1)[tuple(slice(0, k) for k in n)]
    fine = MEANS[lab] * (1 + TEXTURE * tex).astype(np.float32)
    out = tuple(int(e // s) for e, s in zip(CROP_MM, spacing))
    sigma = [s / FINE / 2.355 for s in spacing]              # FWHM one output voxel
    fine = ndi.gaussian_filter(fine, sigma)
    # the output voxel centres on the fine grid (fine index of physical position p: p/FINE - .5)
    centres = [((np.arange(k) + 0.5) * s) / FINE - 0.5 for k, s in zip(out, spacing)]
    grid = np.meshgrid(*centres, indexing="ij")
    clean = ndi.map_coordinates(fine, grid, order=1, mode="nearest")
    # truth: the most frequent label within the output voxel (box average of one-hot)
    frac = np.stack([ndi.map_coordinates(
        ndi.uniform_filter((lab == t).astype(np.float32),
                           [max(1, round(s / FINE)) for s in spacing]), grid, order=1,
        mode="nearest") for t in range(4)])
    brain = frac[0] < 0.5
    truth = np.where(brain, np.argmax(frac[1:], axis=0) + 1, 0).astype(np.int32)
    if bias:
        clean = clean * _poly_field(out, spacing, bias, rng)
    image = clean + noise * MEANS[3] * rng.standard_normal(out)
    return image.astype(np.float32), truth, brain


def cases(variants=VARIANTS, which=CASES):
    """Yield ``(name, (noise, bias, spacing), image, truth, brain)`` for every case."""
    for noise, bias, spacing in variants:
        for crop, anatomy_seed, seed in which:
            image, truth, brain = make_case(crop, anatomy_seed, noise, bias, spacing, seed)
            yield f"{crop}/a{anatomy_seed}/s{seed}", (noise, bias, spacing), image, truth, brain
