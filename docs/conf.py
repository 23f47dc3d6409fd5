"""Sphinx configuration of the napari-swa-imesh documentation.

Build (warnings are errors, as the test ``tests/test_docs_build.py`` and CI build it)::

    python -m sphinx -W --keep-going -n -b html docs docs/_build/html

Pages are MyST Markdown; the Python API comes from the numpydoc docstrings (autosummary),
the command line from the argparse parser itself (``napari_swa_imesh.cli.build_parser``,
through ``_ext/cli_help.py``),
and the benchmark tables from the files the scripts in ``benchmarks/`` write
(``--markdown``), committed under ``docs/benchmarks/generated/``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import napari_swa_imesh

sys.path.insert(0, str(Path(__file__).parent / "_ext"))   # this site's own extension

project = "napari-swa-imesh"
author = "napari-swa-imesh developers"
copyright = "napari-swa-imesh developers"
release = napari_swa_imesh.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "short_refs",
    "cli_help",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "benchmarks/generated"]   # generated pages are included
templates_path = ["_templates"]

myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "inherited-members": False}
autodoc_typehints = "none"          # the numpydoc sections carry the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# references into other projects' documentation are not resolved offline: their names
# stay plain text, and -n (nitpicky) checks every reference inside this site
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|scipy|meshio|pyvista|dask|zarr|napari|pathlib|os|typing|"
               r"collections|argparse|warnings|io|json|h5py|matplotlib|pandas|skfem|sklearn)\..*"),
]

html_theme = "pydata_sphinx_theme"
html_title = "napari-swa-imesh"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
}
html_static_path: list[str] = []
autosummary_ignore_module_all = False
