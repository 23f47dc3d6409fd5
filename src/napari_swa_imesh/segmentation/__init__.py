"""SWA segmentation: tile features at the representative elementary scale, classified.

The pipeline of the reference's chapter 2, as functions on arrays:

* features: :func:`moment_pyramid`, :func:`tile_moments`, :func:`tile_entropy`,
  :func:`tile_correlation_lengths`, :func:`feature_stack` (sets F1..F7);
* samples: :class:`Samples` (JSON sample boxes), :func:`samples_from_truth`;
* RES: :func:`res_statistics`, :func:`plot_res`, :func:`plot_res_scales`;
* classification: :func:`segment` (method "recommended" by default, or "reference"),
  :class:`RecommendedModel` (multi-scale per-pixel statistics, boundary refinement, MRF,
  bias correction), :class:`SWAModel` (the reference: GM, MD, LVQ on tiles),
  :func:`load_model`;
* large images: :func:`predict_chunked` (a saved recommended model chunk by chunk on
  Dask), :func:`apply_model` (an image file to a labels file or Zarr store);
* scores: :func:`dice_scores`, :func:`jaccard_scores`, :func:`confusion_matrix`,
  :func:`evaluate`.
"""

from ._apply import apply_model, wants_chunks
from ._bias import estimate_bias_field
from ._chunked import default_memory, parse_memory, plan_chunks, predict_chunked
from ._classifiers import (
    CLASSIFIERS,
    GaussianClassifier,
    LVQClassifier,
    MinimumDistanceClassifier,
    leave_one_out_error,
)
from ._correlation import tile_correlation_lengths
from ._entropy import entropy_feature_names, tile_entropy
from ._features import FEATURE_SETS, feature_stack, n_features
from ._haar import haar_analysis, haar_synthesis
from ._metrics import confusion_matrix, dice_scores, evaluate, jaccard_scores
from ._model import SWAModel
from ._model_io import load_model
from ._moments import moment_pyramid, tile_moments
from ._mrf import potts_mean_field
from ._recommended import RecommendedModel
from ._res import MOMENT_NAMES, ResStatistics, plot_res, plot_res_scales, res_statistics
from ._samples import (
    Material,
    SampleBox,
    Samples,
    load_samples,
    samples_from_truth,
    save_samples,
)
from ._segment import METHODS, SegmentationResult, segment, segment_steps, sieve_labels
from ._signatures import material_signatures, write_signatures_csv
from ._tiles import majority_tiles, tile_placement, upsample_tiles
from ._window_features import multiscale_feature_names, multiscale_features

__all__ = [
    "CLASSIFIERS", "FEATURE_SETS", "MOMENT_NAMES",
    "GaussianClassifier", "LVQClassifier", "MinimumDistanceClassifier", "leave_one_out_error",
    "Material", "SampleBox", "Samples", "load_samples", "save_samples", "samples_from_truth",
    "ResStatistics", "res_statistics", "plot_res", "plot_res_scales",
    "SWAModel", "load_model", "SegmentationResult", "segment", "segment_steps", "METHODS",
    "RecommendedModel", "estimate_bias_field", "predict_chunked", "plan_chunks",
    "apply_model", "wants_chunks", "default_memory", "parse_memory", "multiscale_feature_names",
    "multiscale_features", "potts_mean_field",
    "sieve_labels", "tile_placement", "upsample_tiles", "majority_tiles",
    "material_signatures", "write_signatures_csv",
    "confusion_matrix", "dice_scores", "evaluate", "jaccard_scores",
    "entropy_feature_names", "feature_stack", "haar_analysis", "haar_synthesis",
    "moment_pyramid", "n_features", "tile_correlation_lengths", "tile_entropy",
    "tile_moments",
]
