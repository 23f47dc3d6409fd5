"""Sample data made on the fly: texture mosaics from scikit-image's photos, a 3-D
tissue phantom and seeded random label images. Used by the demo, the benchmarks, the
tests and the napari sample menu.

Nothing is downloaded: the texture photos (brick, grass, gravel) ship with scikit-image, and
so do the two texture-like pictures added for mosaics of more than three materials: the
lunar surface ("moon") and a 512x512 crop of the Hubble deep field ("hubble", stars and
galaxies on a dark sky, to grey).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from .segmentation import Material, SampleBox, Samples

__all__ = ["TEXTURES", "texture_photo", "texture_mosaic", "texture_training",
           "tissue_phantom", "TISSUE_NAMES", "blob_labels"]

TEXTURES = ("brick", "grass", "gravel", "moon", "hubble")
TISSUE_NAMES = {1: "csf", 2: "grey matter", 3: "white matter"}


def texture_photo(name: str) -> np.ndarray:
    """A 512x512 texture photo of scikit-image, histogram-equalised to [0, 1] (float64).

    Equalisation (as in the reference's mosaics) removes the grey-level differences
    between photos, so only texture tells materials apart.
    """
    from skimage import color, data, exposure

    if name not in TEXTURES:
        raise ValueError(f"unknown texture {name!r}; choose from {', '.join(TEXTURES)}.")
    if name == "hubble":
        # the densest 512x512 part of the field; the photo is RGB
        photo = color.rgb2gray(data.hubble_deep_field())[180:692, 244:756]
    else:
        photo = getattr(data, name)()
    return exposure.equalize_hist(photo)


def texture_training(textures=("brick", "grass")) -> tuple[np.ndarray, Samples]:
    """Training image and samples: the top half (256x512) of each photo, side by side.

    Returns
    -------
    image : (256, 512*K) ndarray of float64
    samples : Samples
        One box per texture covering its half; labels 1..K in the order given.
    """
    halves = [texture_photo(t)[:256] for t in textures]
    image = np.concatenate(halves, axis=1)
    boxes = [SampleBox(i + 1, (0, 512 * i), (256, 512 * (i + 1))) for i in range(len(textures))]
    materials = [Material(i + 1, t) for i, t in enumerate(textures)]
    return image, Samples(materials, boxes)


def texture_mosaic(textures=("brick", "grass"), *, layout: str = "halves", size: int = 256,
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A mosaic of textures taken from the *bottom* halves of the photos (held-out pixels).

    Parameters
    ----------
    textures : sequence of str
        Names from :data:`TEXTURES`; label k+1 is textures[k].
    layout : {"halves", "circle", "voronoi"}
        Straight vertical boundaries (K strips), a disc of texture 2 in texture 1, or
        random Voronoi cells (curved-looking, many boundaries).
    size : int
        Side of the square mosaic (at most 256).
    seed : int
        Seed of the Voronoi sites.

    Returns
    -------
    image : (size, size) ndarray of float64
    truth : (size, size) ndarray of int32
    """
    if not 8 <= size <= 256:
        raise ValueError(f"size must be 8..256 (the held-out half of a photo); got {size}.")
    k = len(textures)
    rr, cc = np.mgrid[:size, :size]
    if layout == "halves":
        truth = (cc * k // size).astype(np.int32) + 1
    elif layout == "circle":
        if k != 2:
            raise ValueError("layout 'circle' takes two textures.")
        r = np.hypot(rr - size / 2 + 0.5, cc - size / 2 + 0.5)
        truth = np.where(r < size * 0.3, 2, 1).astype(np.int32)
    elif layout == "voronoi":
        rng = np.random.default_rng(seed)
        n_sites = 3 * k
        sites = rng.uniform(0, size, (n_sites, 2))
        owner = np.arange(n_sites) % k + 1
        d2 = (rr[..., None] - sites[:, 0]) ** 2 + (cc[..., None] - sites[:, 1]) ** 2
        truth = owner[np.argmin(d2, axis=-1)].astype(np.int32)
    else:
        raise ValueError(f"unknown layout {layout!r}; choose halves, circle or voronoi.")
    image = np.zeros((size, size))
    for i, t in enumerate(textures):
        held_out = texture_photo(t)[256:256 + size, :size]
        image[truth == i + 1] = held_out[truth == i + 1]
    return image, truth


def _smooth_field(shape, rng, sigma_frac: float) -> np.ndarray:
    """Smooth random field in about [-1, 1], made at low resolution and zoomed up."""
    small = tuple(max(4, int(round(n / 8))) for n in shape)
    f = ndi.gaussian_filter(rng.standard_normal(small), sigma=max(1.0, sigma_frac * min(small)),
                            mode="wrap")
    f = ndi.zoom(f, [n / s for n, s in zip(shape, small)], order=1)
    f = f[tuple(slice(0, n) for n in shape)]
    return f / (np.abs(f).max() + 1e-12)


def tissue_phantom(shape=(64, 96, 96), *, noise: float = 0.03, bias: float = 0.0,
                   spacing=(2.0, 1.0, 1.0), seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A brain-like 3-D phantom: CSF around and inside, a folded grey-matter shell, white core.

    Parameters
    ----------
    shape : tuple of int
        Volume shape (plane, row, column).
    noise : float
        Rician noise level as a fraction of the white-matter intensity (BrainWeb's
        convention: 0.03 and 0.09 are "3%" and "9%").
    bias : float
        Amplitude of a smooth multiplicative intensity bias (0.4 = "40% INU").
    spacing : tuple of float
        Voxel size; the anatomy is made round in physical units, so anisotropic spacing
        gives the same shapes with fewer planes.
    seed : int

    Returns
    -------
    image : ndarray of float32
        T1-like intensities (CSF 0.25, grey 0.55, white 0.8) with noise and bias.
    truth : ndarray of int32
        1 = CSF, 2 = grey matter, 3 = white matter (:data:`TISSUE_NAMES`).
    """
    rng = np.random.default_rng(seed)
    sp = np.asarray(spacing, float)
    ext = np.asarray(shape) * sp
    grids = np.meshgrid(*[(np.arange(n) + 0.5) * s - e / 2 for n, s, e in zip(shape, sp, ext)],
                        indexing="ij", sparse=True)
    semi = ext / 2 * np.array([0.97, 0.97, 0.95])[: len(shape)]
    rho = np.sqrt(sum((g / a) ** 2 for g, a in zip(grids, semi)))   # 1 on the brain surface
    folds = _smooth_field(shape, rng, 0.15)
    wobble = _smooth_field(shape, rng, 0.3)
    truth = np.ones(shape, np.int32)
    outer = rho + 0.06 * wobble
    truth[outer < 0.92] = 2
    truth[outer + 0.12 * folds < 0.70] = 3
    # two ventricles: CSF inside the white matter
    for side in (-1, 1):
        c = [0.0] * len(shape)
        c[-1] = side * 0.18 * ext[-1] / 2
        vent = np.sqrt(sum(((g - ci) / (a * w)) ** 2 for g, ci, a, w in
                           zip(grids, c, semi, [0.35, 0.5, 0.12][: len(shape)])))
        truth[vent < 1] = 1
    mean = np.array([0.0, 0.25, 0.55, 0.80])
    texture = 0.02 * _smooth_field(shape, rng, 0.02)
    clean = mean[truth] + texture
    # partial-volume effect: a voxel sees a little of its neighbours, as in real scans
    clean = ndi.gaussian_filter(clean, sigma=0.6 / sp * sp.min())
    if bias:
        field = _smooth_field(shape, rng, 0.5)
        axis_ramp = np.linspace(-1, 1, shape[0]).reshape((-1,) + (1,) * (len(shape) - 1))
        clean = clean * (1 + bias / 2 * np.clip(0.5 * field + 0.5 * axis_ramp, -1, 1))
    sigma = noise * mean[3]
    image = np.sqrt((clean + sigma * rng.standard_normal(shape)) ** 2
                    + (sigma * rng.standard_normal(shape)) ** 2)
    return image.astype(np.float32), truth


def blob_labels(shape, n_materials: int, *, seed: int, sigma: float = 2.0) -> np.ndarray:
    """Smooth random regions: big homogeneous blocks with boundaries of every slope.

    Uniform noise smoothed by a Gaussian of `sigma` pixels, cut at its quantiles into
    `n_materials` labels of about equal volume. The meshing tests and benchmarks use it.

    Parameters
    ----------
    shape : tuple of int
        Image shape (plane, row, column), any dimension.
    n_materials : int
        Number of labels, at least 1.
    seed : int
        Seed of the random generator: the same seed gives the same labels.
    sigma : float
        Smoothing in pixels; larger gives larger regions.

    Returns
    -------
    labels : ndarray of int64, shape `shape`
        Labels 0 .. `n_materials` - 1.

    Examples
    --------
    >>> labels = blob_labels((16, 16), 3, seed=0)
    >>> labels.shape, sorted(set(labels.ravel().tolist()))
    ((16, 16), [0, 1, 2])
    """
    shape = tuple(int(n) for n in np.atleast_1d(shape))
    if not shape or min(shape) < 1:
        raise ValueError(f"blob_labels needs a shape of positive sizes, got {shape}")
    if int(n_materials) < 1:
        raise ValueError(f"blob_labels needs at least one material, got {n_materials}")
    rng = np.random.default_rng(seed)
    field = ndi.gaussian_filter(rng.random(shape), sigma)
    cuts = np.quantile(field, np.linspace(0, 1, int(n_materials) + 1)[1:-1])
    return np.digitize(field, cuts).astype(np.int64)
