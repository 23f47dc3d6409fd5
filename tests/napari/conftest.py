"""Fixtures of the widget tests: a viewer with a sample loaded, notifications."""

from __future__ import annotations

import pytest
from swa_napari_helpers import PHANTOM_SHAPE, Notifications, add_layer_data

from napari_swa_imesh._napari._sample_data import make_texture_mosaic, make_tissue_phantom


@pytest.fixture
def mosaic_viewer(make_napari_viewer):
    viewer = make_napari_viewer()
    image, truth = add_layer_data(viewer, make_texture_mosaic())
    return viewer, image, truth


@pytest.fixture
def phantom_viewer(make_napari_viewer):
    viewer = make_napari_viewer()
    image, truth = add_layer_data(viewer, make_tissue_phantom(shape=PHANTOM_SHAPE))
    return viewer, image, truth


@pytest.fixture
def notifications():
    return Notifications()
