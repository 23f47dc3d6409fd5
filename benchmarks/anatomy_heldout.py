"""A second, independent MR phantom generator: the held-out one nothing is tuned on.

:mod:`anatomy` (the *tuning* generator) turns the MNI152 probability maps into intensities
by tissue-probability mixing, Rician noise and a random-Gaussian bias field at 1 mm. This
one shares only the anatomy source and differs in every step from anatomy to intensity:

* **labels, then a PSF**: each voxel of a 0.5 mm grid takes its most probable tissue (hard
  labels, sharper sulci than the maps' average), the intensity of that label where it lies
  (below), and the scanner's point-spread function (Gaussian, FWHM :data:`PSF_FWHM` output
  voxels per axis) and the
  averaging over the output voxel make the partial volume;
* **other contrast ratios**: T1 (CSF 0.20, GM 0.62, WM 0.86 against 0.25 / 0.55 / 0.80) and
  T2 (CSF 1.00, GM 0.62, WM 0.48: the order reversed);
* **tissue intensity that depends on where the tissue is**, as on real scans, so that no
  class mean describes a whole class and the boxes (the largest homogeneous blocks: deep
  tissue) are not typical of it: grey matter far from CSF (deep nuclei) lies
  :data:`DEEP_GM` of the way towards white matter, white matter within a few mm of grey
  matter (U-fibres) :data:`SUBCORTICAL_WM` of its mean darker (in T1; T2 alike, towards
  grey), and a within-tissue texture (smooth, 3 %);
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

__all__ = ["CASES", "CONTRASTS", "CROP_MM", "MEANS", "VARIANTS", "cases", "make_case"]

CONTRASTS = {"T1": np.array([0.0, 0.20, 0.62, 0.86], np.float32),   # bg, CSF, GM, WM
             "T2": np.array([0.0, 1.00, 0.62, 0.48], np.float32)}
MEANS = CONTRASTS["T1"]
ISO, ANISO = (1.0, 1.0, 1.0), (1.5, 0.94, 0.94)
# (contrast, noise, bias, spacing): 1 mm and 1.5 x 0.94 x 0.94 mm voxels
VARIANTS = [("T1", 0.03, 0.0, ISO), ("T1", 0.03, 0.4, ISO), ("T1", 0.09, 0.0, ISO),
            ("T1", 0.09, 0.4, ISO), ("T1", 0.03, 0.0, ANISO), ("T1", 0.03, 0.4, ANISO),
            ("T2", 0.03, 0.0, ISO), ("T2", 0.03, 0.4, ISO)]
CROP_MM = (48.0, 72.0, 108.0)   # physical extent of a crop (z, y, x), inside a quadrant
# (quadrant, anatomy seed, noise seed); the held-out quadrants of the tuning generator
CASES = [("inf-ant", 7, 71), ("sup-post", 8, 81)]
TEXTURE = 0.03
FINE = 0.5                      # mm of the hard-label grid
DEEP_GM = 0.3                   # deep GM: this fraction of the way from GM to WM ...
DEEP_GM_MM = 4.0                # ... reached with this length of distance from CSF
SUBCORTICAL_WM = 0.06           # WM next to GM: this much darker (T1), fading over ...
SUBCORTICAL_MM = 3.0            # ... this length
PSF_FWHM = 1.2                  # output voxels per axis


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


def _tissue_intensity(lab: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Intensity of every 0.5 mm label voxel: its class mean, moved by where it lies
    (deep grey matter towards white, white matter next to grey towards grey)."""
    mm = FINE * np.float32(1)
    d_csf = ndi.distance_transform_edt(lab != 1).astype(np.float32) * mm
    d_gm = ndi.distance_transform_edt(lab != 2).astype(np.float32) * mm
    out = means[lab].astype(np.float32)
    gm, wm = lab == 2, lab == 3
    deep = 1 - np.exp(-np.maximum(d_csf - FINE, 0) / DEEP_GM_MM)
    out[gm] += (DEEP_GM * (means[3] - means[2]) * deep[gm]).astype(np.float32)
    near = np.exp(-np.maximum(d_gm - FINE, 0) / SUBCORTICAL_MM)
    out[wm] -= (SUBCORTICAL_WM * abs(means[3]) * np.sign(means[3] - means[2])
                * near[wm]).astype(np.float32)
    return out


def make_case(crop: str, anatomy_seed: int, noise: float, bias: float, spacing, seed: int,
              contrast: str = "T1") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(image float32, truth int32, brain bool) of one held-out case."""
    means = CONTRASTS[contrast]
    lab, n = _fine_labels(crop, anatomy_seed)
    rng = np.random.default_rng(seed)
    # intensities of the labels where they lie, a smooth within-tissue texture, then the
    # PSF and the voxel
    tex = ndi.gaussian_filter(rng.standard_normal(tuple(k // 4 for k in n)), 2.0)
    tex = ndi.zoom(tex / (tex.std() + 1e-12), [k / s for k, s in zip(n, tex.shape)],
                   order=1)[tuple(slice(0, k) for k in n)]
    fine = _tissue_intensity(lab, means) * (1 + TEXTURE * tex).astype(np.float32)
    out = tuple(int(e // s) for e, s in zip(CROP_MM, spacing))
    sigma = [PSF_FWHM * s / FINE / 2.355 for s in spacing]
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
        # the field from a stream of its own, so a case with a field and without it share
        # the texture and the noise, and differ in the field alone
        clean = clean * _poly_field(out, spacing, bias, np.random.default_rng([seed, 7]))
    image = clean + noise * MEANS[3] * rng.standard_normal(out)   # sigma: % of T1 WM
    return image.astype(np.float32), truth, brain


def cases(variants=VARIANTS, which=CASES):
    """Yield ``(name, (contrast, noise, bias, spacing), image, truth, brain)`` for every
    case."""
    for contrast, noise, bias, spacing in variants:
        for crop, anatomy_seed, seed in which:
            image, truth, brain = make_case(crop, anatomy_seed, noise, bias, spacing, seed,
                                            contrast)
            yield (f"{crop}/a{anatomy_seed}/s{seed}", (contrast, noise, bias, spacing),
                   image, truth, brain)
