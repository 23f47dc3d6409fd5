"""Fitting on a large image reads only the sample boxes (and a chunked pass for the bias
field): the model and its labels equal the in-memory fit's."""

import tracemalloc

import dask.array as da
import numpy as np
import pytest

from napari_swa_imesh._zarr_io import open_lazy
from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import (
    RecommendedModel,
    Samples,
    _recommended,
    samples_from_truth,
)
from napari_swa_imesh.segmentation._chunked_fit import _first_cover, fit_chunked


def _calm_and_busy(n=96, seed=1):
    """Calm | busy noise with a 40 % multiplicative ramp: a texture model whose bias
    field is labelled by level 1 (the chunked labelling pass, not the strided copy)."""
    rng = np.random.default_rng(seed)
    ramp = 1 + 0.4 * np.arange(2 * n) / (2 * n)
    img = np.concatenate([rng.normal(10, 1, (n, n)), rng.normal(10.5, 3, (n, n))], 1)
    samples = Samples.from_dict({"boxes": [
        {"label": 1, "start": [0, 0], "stop": [n, n - 8]},
        {"label": 2, "start": [0, n + 8], "stop": [n, 2 * n]}]})
    return (img * ramp).astype(np.float32), samples


def _phantom_3d():
    image, truth = tissue_phantom((40, 48, 48), noise=0.06, bias=0.3, spacing=(1, 1, 1))
    return image, samples_from_truth(truth)          # boxes of 4^3 and 8^3 voxels


@pytest.mark.parametrize("case,options,finest", [
    ("texture", {"bias_correction": True, "max_scale": 4, "pixels_per_material": 3000}, 1),
    ("phantom", {"bias_correction": True, "max_scale": 2}, 0),     # the strided copy
    ("phantom", {}, 0),
])
def test_chunked_fit_equals_the_in_memory_fit(case, options, finest, monkeypatch):
    image, samples = _calm_and_busy() if case == "texture" else _phantom_3d()
    # a store's fit keeps the box means (the interiors' means need the whole image,
    # _refine_em): compare with the in-memory fit without that step
    monkeypatch.setattr(_recommended, "refine_fitted", lambda m, s: {"applied": False})
    ref = RecommendedModel(**options).fit(image, samples)
    monkeypatch.undo()
    lazy = da.from_array(image, chunks=8)
    model = fit_chunked(RecommendedModel(**options), lazy, samples,
                        chunks=(24,) * image.ndim, scheduler="sync")
    assert model.finest_scale == ref.finest_scale == finest
    assert (model.scale, model.bias_correction) == (ref.scale, ref.bias_correction)
    assert model.intensity == ref.intensity
    assert not model.scores["refined_means"]["applied"]
    if ref.bias_correction:
        np.testing.assert_allclose(model.scores["bias_range"], ref.scores["bias_range"],
                                   rtol=1e-4)
    a, b = ref.predict(image), model.predict(image)
    inner = tuple(slice(8, n - 8) for n in image.shape)
    assert (a[inner] == b[inner]).mean() >= 0.995
    assert len(np.unique(a)) == len(samples.materials)       # the models do segment


def test_fit_never_holds_a_copy_of_the_image(tmp_path):
    image, truth = tissue_phantom((128, 128), noise=0.06, bias=0.3, spacing=(1, 1))
    samples = samples_from_truth(truth)
    fit_chunked(RecommendedModel(), image, samples, chunks=(64, 64))     # imports done
    big = np.tile(image, (8, 8))                  # 1024x1024 float32: 4.2 MB on disk
    np.save(tmp_path / "img.npy", big)
    nbytes = big.nbytes
    del big
    lazy, _ = open_lazy(tmp_path / "img.npy", chunks=(128, 128))
    tracemalloc.start()
    model = fit_chunked(RecommendedModel(bias_correction=True), lazy, samples,
                        chunks=(128, 128), scheduler="sync")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert model.bias_correction and model.finest_scale == 0
    # the boxes, the every-16th-voxel copy the field is labelled on and one chunk at a
    # time in the minimum pass; the in-memory fit holds two float32 copies and more
    assert peak < nbytes / 2


def test_boxes_larger_than_the_budget_are_refused():
    image, samples = _calm_and_busy()
    with pytest.raises(ValueError, match=r"training on these sample boxes needs about "
                                         r"0\.\d+ GB .* draw smaller boxes"):
        fit_chunked(RecommendedModel(), image, samples, memory=10**6)


def test_union_of_overlapping_boxes_counts_each_voxel_once():
    s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [4, 6]},
                                     {"label": 2, "start": [2, 3], "stop": [7, 8]},
                                     {"label": 1, "start": [1, 1], "stop": [3, 4]}]})
    mask = np.zeros((8, 8), int)
    for b in s.boxes:
        mask[b.slices] = 1
    assert sum(int(_first_cover(s.boxes, i).sum()) for i in range(3)) == mask.sum() == 24 + 25 - 6
