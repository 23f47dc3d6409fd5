"""The cohort pipeline: segment -> mesh -> simulate, above the three steps.

* :func:`run_batch`: a cohort of images segmented with one saved model on
  ``dask.distributed``, each image's labels optionally meshed and simulated;
* :func:`segment_one`, :func:`simulate_labels`: one image's task, one labels file's k_eff;
* :func:`expand_inputs`, :func:`output_for`, :func:`mesh_for`: the inputs and the names
  of the outputs; :func:`connect`: the cluster.

Segmentation, mesh and simulate are peers below this package (simulate uses mesh); only
the pipeline chains them.
"""

from ._batch import (
    CONNECT_SECONDS,
    DETERMINISTIC,
    connect,
    expand_inputs,
    mesh_for,
    missing_folders,
    output_for,
    quiet_dask,
    run_batch,
    segment_one,
    simulate_labels,
)

__all__ = ["expand_inputs", "output_for", "mesh_for", "connect", "run_batch", "segment_one",
           "simulate_labels", "missing_folders", "quiet_dask", "CONNECT_SECONDS",
           "DETERMINISTIC"]
