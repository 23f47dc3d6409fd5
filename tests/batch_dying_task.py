"""A batch task whose worker process dies (SIGKILL) right after its first try wrote the
outputs: imported by the Dask worker processes of ``test_batch_failures`` by name."""

import os
import signal
from pathlib import Path

from napari_swa_imesh.pipeline import _batch


def segment_then_die_once(image, model_path, output, **kwargs):
    marker = Path(output).parent.parent / "first-try-done"
    row = _batch.segment_one(image, model_path, output, **kwargs)
    if not marker.exists():
        marker.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return row
