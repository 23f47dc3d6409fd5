"""Every example in the library's docstrings runs and prints what it says."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import napari_swa_imesh

LIBRARY = sorted(
    m.name for m in pkgutil.walk_packages(napari_swa_imesh.__path__, "napari_swa_imesh.")
    if "._napari" not in m.name
)


@pytest.mark.parametrize("name", LIBRARY)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{result.failed} docstring example(s) of {name} failed"
