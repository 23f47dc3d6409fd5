"""File > Open Sample: a 2-D texture mosaic and a 3-D tissue phantom, each with its truth."""

from __future__ import annotations

from ..data import TISSUE_NAMES, texture_mosaic, tissue_phantom
from ._layers import labels_colormap, material_palette

__all__ = ["make_texture_mosaic", "make_tissue_phantom", "MOSAIC_TEXTURES"]

MOSAIC_TEXTURES = ("brick", "grass")


def make_texture_mosaic(*, layout: str = "circle", size: int = 256) -> list[tuple]:
    """A disc of grass in brick (held-out halves of scikit-image's photos) and its truth.

    Returns
    -------
    list of (data, kwargs, layer_type)
        An image layer and a labels layer named ``"texture mosaic"`` and
        ``"texture mosaic truth"``; the truth's metadata holds the material names.
    """
    image, truth = texture_mosaic(MOSAIC_TEXTURES, layout=layout, size=size)
    names = {i + 1: t for i, t in enumerate(MOSAIC_TEXTURES)}
    return [
        (image, {"name": "texture mosaic", "colormap": "gray"}, "image"),
        (truth, {"name": "texture mosaic truth", "opacity": 0.4,
                 "colormap": labels_colormap(material_palette(names)),
                 "metadata": {"material_names": names}}, "labels"),
    ]


def make_tissue_phantom(*, shape=(64, 96, 96), spacing=(2.0, 1.0, 1.0), noise: float = 0.05,
                        seed: int = 0) -> list[tuple]:
    """A 3-D brain-like phantom (CSF, grey and white matter) with 2:1:1 voxels, and its truth.

    The voxel spacing becomes the layers' ``scale``, so the anatomy looks round on screen
    and every output of the plugin (sample boxes, labels, mesh) is placed in physical
    units.
    """
    image, truth = tissue_phantom(shape, noise=noise, spacing=spacing, seed=seed)
    names = dict(TISSUE_NAMES)
    scale = tuple(float(s) for s in spacing)
    return [
        (image, {"name": "tissue phantom", "scale": scale, "colormap": "gray"}, "image"),
        (truth, {"name": "tissue phantom truth", "scale": scale, "opacity": 0.4,
                 "colormap": labels_colormap(material_palette(names)),
                 "metadata": {"material_names": names}}, "labels"),
    ]
