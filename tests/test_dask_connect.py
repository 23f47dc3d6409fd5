"""One description of the Dask connection's parameters: ``pipeline.connect`` documents the
ones it passes on with :func:`connect_dask`'s own entries, filled in on import."""

from __future__ import annotations

import inspect

import pytest

from napari_swa_imesh._dask_connect import connect_dask, with_dask_parameters
from napari_swa_imesh.pipeline import connect


def test_connect_documents_connect_dasks_parameters_in_full():
    numpydoc = pytest.importorskip("numpydoc.docscrape")
    mine = numpydoc.NumpyDocString(inspect.getdoc(connect))
    theirs = {p.name: p for p in numpydoc.NumpyDocString(inspect.getdoc(connect_dask))
              ["Parameters"]}
    assert [p.name for p in mine["Parameters"]] == ["scheduler", "workers", "memory"]
    for p in mine["Parameters"]:
        assert p == theirs[p.name] and p.desc, p.name
    assert set(inspect.signature(connect).parameters) == {"scheduler", "workers", "memory"}
    assert "<connect_dask" not in inspect.getdoc(connect)


def test_a_docstring_without_the_line_or_with_a_stray_name_is_refused():
    def plain():
        """Nothing to fill in."""

    with pytest.raises(ValueError, match="has no <connect_dask: ...> line"):
        with_dask_parameters(plain)

    def stray():
        """Parameters
        ----------
        <connect_dask: scheduler, threads>
        """

    with pytest.raises(ValueError, match="names threads, which connect_dask does not take"):
        with_dask_parameters(stray)
