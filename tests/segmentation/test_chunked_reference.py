"""A reference (tile) model chunk by chunk: chunks aligned to the tiles equal the whole
image exactly, for every feature set, in 2-D and 3-D."""

import tracemalloc

import numpy as np
import pytest

from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import SWAModel, predict_chunked, samples_from_truth
from napari_swa_imesh.segmentation._chunked_reference import (
    BYTES_PER_VOXEL,
    _labels_tiles,
    plan_tiles,
    tile_chunks,
)


@pytest.fixture(scope="module")
def scenes():
    out = {}
    for shape in ((45, 70), (30, 34, 38)):
        image, truth = tissue_phantom(shape, noise=0.08, bias=0.2, spacing=(1.0,) * len(shape))
        out[len(shape)] = image, samples_from_truth(truth, scale=2)
    return out


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("feature_set,scale", [("F1", 1), ("F1", 2), ("F2", 2), ("F3", 2),
                                               ("F7", 2)])
def test_tiny_aligned_chunks_equal_the_whole_image(scenes, ndim, feature_set, scale):
    image, samples = scenes[ndim]
    model = SWAModel(scale=scale, feature_set=feature_set).fit(image, samples)
    whole = model.predict(image)
    side = 1 << scale
    labels, plan = predict_chunked(model, image, chunks=(2 * side + 1,) * ndim,
                                   scheduler="sync")
    assert plan["halo"] == 0 and plan["chunks"] == (2 * side,) * ndim
    # several chunks per axis; partial tiles at the far faces in their last chunk
    assert all(len(c) > 1 for c in labels.chunks)
    assert any(c[-1] % side for c in labels.chunks) == any(n % side for n in image.shape)
    got = labels.compute(scheduler="sync")
    np.testing.assert_array_equal(got, whole)
    assert len(np.unique(whole)) > 1


def test_chunks_shifted_off_the_tile_grid_would_differ(scenes):
    image, samples = scenes[2]
    model = SWAModel(scale=2).fit(image, samples)
    shifted = np.concatenate([model.predict(image[:, :6]), model.predict(image[:, 6:])], 1)
    assert (shifted != model.predict(image)).any()           # why chunks follow the tiles


def test_remainders_shorter_than_a_tile_join_the_chunk_before():
    assert tile_chunks((20, 9, 30), (8, 8, 8), 4) == ((8, 8, 4), (9,), (8, 8, 8, 6))
    assert tile_chunks((3, 64), (8, 16), 8) == ((3,), (16, 16, 16, 16))


def test_plan_fits_the_budget_and_bounds_the_measured_peak(scenes):
    image, samples = scenes[2]
    model = SWAModel(scale=2, feature_set="F7").fit(image, samples)
    core, workers = plan_tiles((4096, 4096), model, 64 * 2**20, workers=1)
    assert all(c % 4 == 0 for c in core)
    assert np.prod([c + 4 for c in core]) * BYTES_PER_VOXEL <= 64 * 2**20
    with pytest.raises(ValueError, match=r"a chunk of one tile of 4 px per axis needs"):
        plan_tiles((4096, 4096), model, 1000)
    # the worst case measured (F7 at scale 2, 2-D): one chunk within its per-voxel cost
    block = np.random.default_rng(0).normal(size=(256, 256))

    info = [{"array-location": [(0, 256), (0, 256)]}]
    _labels_tiles(None, lambda lo, hi: block, model, np.uint8, block_info=info)        # warm
    tracemalloc.start()
    _labels_tiles(None, lambda lo, hi: block, model, np.uint8, block_info=info)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak <= BYTES_PER_VOXEL * block.size
