"""The benchmark scripts, importable as a package so the tests can check their generators.

Each script runs on its own (``python benchmarks/bench_mesh.py``: its folder is then first
on ``sys.path``, so the scripts import one another by name). The tests import the phantom
generators as ``from benchmarks import anatomy`` (the repository root is on pytest's path,
``pythonpath`` in ``pyproject.toml``). Neither side puts the other's folder on
``sys.path``; code both need lives in the package (``napari_swa_imesh.data``).
"""
