"""tests/ and benchmarks/ do not reach into each other through sys.path.

Code both need lives in the package (``napari_swa_imesh.data.blob_labels``) or is imported
from the ``benchmarks`` package (``from benchmarks import anatomy``), never by putting the
other folder on ``sys.path``.
"""

import re
from pathlib import Path

import numpy as np
import pytest

from napari_swa_imesh.data import blob_labels

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("folder, other", [("tests", "benchmarks"), ("benchmarks", "tests")])
def test_no_sys_path_reach_into_the_other_folder(folder, other):
    offenders = []
    for path in (ROOT / folder).rglob("*.py"):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"sys\.path\.(insert|append)", line) and other in line:
                offenders.append(f"{path.relative_to(ROOT)}:{number}")
    assert not offenders, offenders


def test_blob_labels_are_seeded_and_cover_every_material():
    a = blob_labels((20, 30), 4, seed=3)
    assert a.dtype == np.int64 and a.shape == (20, 30)
    assert np.array_equal(a, blob_labels((20, 30), 4, seed=3))
    assert not np.array_equal(a, blob_labels((20, 30), 4, seed=4))
    counts = np.bincount(a.ravel(), minlength=4)
    assert counts.size == 4 and counts.min() >= 0.2 * a.size   # quantile cuts: ~1/4 each


@pytest.mark.parametrize("shape, n", [((0, 4), 2), ((4, 4), 0)])
def test_blob_labels_refuses_empty_shapes_and_no_material(shape, n):
    with pytest.raises(ValueError, match="blob_labels needs"):
        blob_labels(shape, n, seed=0)
