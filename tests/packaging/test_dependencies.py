"""The plain install brings what the code imports; the Qt binding stays the user's.

Every third-party module the napari widgets import (at any depth: inside functions too) and
every module the rest of the package imports at module level comes from a distribution in
``[project] dependencies``, or, for a module of one path only (``_extras.EXTRAS``: the
chunked path, XDMF files), from the extra that :func:`~napari_swa_imesh._extras.require`
names at that path's door; napari itself is the host and may be left to the user, and no Qt
binding is pinned (napari's plugin guide: the user picks PyQt or PySide). The slow proof
that the widgets then dock and run is ``test_napari_install.py``.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

from napari_swa_imesh._extras import EXTRAS

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "src" / "napari_swa_imesh"
HOST = {"napari"}                  # the application the plugin runs in
QT_BINDINGS = {"pyqt5", "pyqt6", "pyside2", "pyside6"}


def _name(requirement: str) -> str:
    return re.split(r"[\s<>=!~;\[]", requirement, maxsplit=1)[0].lower().replace("_", "-")


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _base_dependencies() -> set[str]:
    return {_name(r) for r in _project()["dependencies"]}


def _extra(name: str) -> set[str]:
    return {_name(r) for r in _project()["optional-dependencies"][name]}


def _imports(path: Path, *, nested: bool) -> set[str]:
    tree = ast.parse(path.read_text())
    nodes = ast.walk(tree) if nested else tree.body
    found = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
    return found


def _imported_distributions() -> dict[str, set[str]]:
    """Distribution -> the package files importing it (standard library left out)."""
    owners = packages_distributions()
    found: dict[str, set[str]] = {}
    for path in PACKAGE.rglob("*.py"):
        nested = "_napari" in path.relative_to(PACKAGE).parts
        for module in _imports(path, nested=nested):
            if module in sys.stdlib_module_names or module == "napari_swa_imesh":
                continue
            for dist in owners.get(module, [module]):
                found.setdefault(dist.lower().replace("_", "-"), set()).add(path.name)
    return found


def test_the_plain_install_brings_every_imported_distribution():
    base = _base_dependencies()
    optional = set(EXTRAS)                  # imported behind require(), which names the extra
    missing = {dist: sorted(files) for dist, files in _imported_distributions().items()
               if dist not in base | HOST | optional}
    assert not missing, f"imported but not in [project] dependencies: {missing}"


def _own_extras(extra: str) -> set[str]:
    """The extras of this package that the extra `extra` pulls (``napari-swa-imesh[a,b]``)."""
    found = set()
    for requirement in _project()["optional-dependencies"][extra]:
        own = re.fullmatch(r"napari-swa-imesh\[([^\]]*)\]", requirement.strip())
        if own:
            found.update(part.strip() for part in own.group(1).split(","))
    return found


def test_each_optional_module_is_in_the_extra_its_message_names_and_not_required():
    base = _base_dependencies()
    for module, extra in EXTRAS.items():
        assert module in _extra(extra), (module, extra)
        assert module not in base, module
    assert set(EXTRAS.values()) <= _own_extras("all")


def test_the_testing_extra_pulls_every_path_so_ci_tests_everything():
    assert "all" in _own_extras("testing")


def test_no_qt_binding_and_no_napari_in_the_base_dependencies():
    assert not _base_dependencies() & (QT_BINDINGS | HOST)


def test_the_check_sees_the_widgets_imports():
    # the widgets' own imports are found (a check that found nothing would pass anyway)
    found = _imported_distributions()
    for dist in ("napari-matplotlib", "magicgui", "qtpy", "pandas", "napari"):
        assert dist in found, dist
