"""Segment: train on two texture photos, label a mosaic of their held-out halves.

The recommended SWA method picks its scales from the samples' RES statistics; the Dice
against the mosaic's truth says how well it did.
"""

from napari_swa_imesh.data import texture_mosaic, texture_training
from napari_swa_imesh.segmentation import evaluate, segment

train, samples = texture_training(("brick", "grass"))    # top halves, one box per photo
fitted = segment(train, samples)                          # recommended method
mosaic, truth = texture_mosaic(("brick", "grass"), size=128)
result = segment(mosaic, model=fitted.model)              # apply the fitted model

dice = evaluate(result.labels, truth)["dice"]
print("scale", result.scale, "Dice", dice)
assert result.labels.shape == mosaic.shape
assert min(dice.values()) > 0.85, dice
