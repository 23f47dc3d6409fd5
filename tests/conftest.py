"""Suite-wide marks: the heavy tests are ``slow``, so ``pytest -m "not slow"`` is quick.

Listed here by file (one place, not a decorator per test): a file whose tests build a fresh
environment, run the whole demo in a subprocess, start a Dask cluster or load the anatomy
benchmark's data. Every ``install`` test is slow too.
"""

from __future__ import annotations

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent

#: test files (relative to tests/) whose every test is slow
SLOW_FILES = {
    "packaging/test_napari_install.py",     # a fresh venv with napari, ~2 min
    "test_anatomy_benchmark.py",            # the MNI152 tissue maps, anatomy phantoms
    "test_demo.py",                         # the whole demo, in subprocesses
    "test_cli_batch.py",                    # a dask.distributed cluster per test
    "napari/test_workflow_3d.py",           # the 3-D workflow through every widget
    "simulate/test_curl.py",                # 3-D curl bounds against finer P2 solves
}


def pytest_collection_modifyitems(config, items):
    for item in items:
        path = Path(str(item.fspath)).resolve()
        name = path.relative_to(HERE).as_posix() if HERE in path.parents else ""
        if name in SLOW_FILES or item.get_closest_marker("install"):
            item.add_marker(pytest.mark.slow)
