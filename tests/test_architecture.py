"""The shape of the house (issue 14), checked on the source tree with ``ast``.

- no import cycle between the package's modules (function-level imports included: a cycle
  hidden inside a function is still a cycle);
- library modules never import command-line modules (``_cli_util``, ``*._cli``, ``cli``,
  ``_demo``);
- no module over 500 lines;
- one atomic writer: only ``_atomic.py`` (re-exported by ``io.py``) renames files into place.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

PACKAGE = "napari_swa_imesh"
SRC = Path(__file__).resolve().parents[1] / "src" / PACKAGE
MAX_LINES = 500


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(SRC.rglob("*.py"))}


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _resolve(module: str, node: ast.ImportFrom | ast.Import) -> list[str]:
    """Package modules that an import statement in `module` loads."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name in MODULES]
    if node.level:
        base = module if _is_package(module) else module.rpartition(".")[0]
        for _ in range(node.level - 1):
            base = base.rpartition(".")[0]
        target = f"{base}.{node.module}" if node.module else base
    else:
        target = node.module or ""
    found = []
    for alias in node.names:                     # `from pkg import submodule`
        sub = f"{target}.{alias.name}"
        if sub in MODULES:
            found.append(sub)
        elif target in MODULES:
            found.append(target)
    return found


def _imports(name: str) -> set[str]:
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out.update(_resolve(name, node))
    out.discard(name)
    return out


GRAPH = {name: _imports(name) for name in MODULES}


def _cycles() -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan).

    Edges into a package's ``__init__`` from inside that package are left out: a
    submodule reading ``__version__`` from its package is the facade pattern, not a cycle
    of implementation modules.
    """
    def edges(a: str) -> list[str]:
        return [b for b in GRAPH[a] if not (_is_package(b) and a.startswith(b + "."))]

    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in GRAPH:
        if v not in index:
            visit(v)
    return found


def _is_command_line(name: str) -> bool:
    last = name.rpartition(".")[2]
    return last in {"cli", "_cli", "_cli_util", "_demo"}


def test_the_import_graph_sees_known_edges():
    # guards the checker itself: a resolver that finds nothing would pass every test
    assert f"{PACKAGE}._cli_util" in GRAPH[f"{PACKAGE}.mesh._cli"]
    assert f"{PACKAGE}.io" in GRAPH[f"{PACKAGE}.segmentation._cli"]
    assert len(MODULES) > 30


def test_no_import_cycle():
    assert _cycles() == []


def test_a_planted_cycle_is_found(monkeypatch):
    a, b = f"{PACKAGE}.io", f"{PACKAGE}.mesh.mesher._balance"
    monkeypatch.setitem(GRAPH, a, GRAPH[a] | {b})
    monkeypatch.setitem(GRAPH, b, GRAPH[b] | {a})
    assert any(a in c and b in c for c in _cycles())


@pytest.mark.parametrize("name", sorted(n for n in MODULES if not _is_command_line(n)
                                        and not n.startswith(f"{PACKAGE}._napari")))
def test_library_modules_do_not_import_command_line_modules(name):
    bad = sorted(m for m in GRAPH[name] if _is_command_line(m))
    assert bad == [], f"{name} imports command-line modules {bad}"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_module_over_500_lines(name):
    n = len(MODULES[name].read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"{name} has {n} lines"


def _attribute_calls(name: str) -> set[str]:
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    return {f"{n.value.id}.{n.attr}" for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_only_io_moves_files_into_place(name):
    if name == f"{PACKAGE}._atomic":
        return
    moving = _attribute_calls(name) & {"os.replace", "os.rename", "os.link", "shutil.move",
                                       "tempfile.mkstemp", "tempfile.NamedTemporaryFile"}
    assert moving == set(), f"{name} writes files around io.atomic_write: {moving}"


def test_the_atomic_writer_is_where_the_rename_rule_looks():
    assert {"os.replace", "os.rename", "os.link"} <= _attribute_calls(f"{PACKAGE}._atomic")


# --- The house rules across packages (issue 24) --------------------------------------
#
# A *package* is a sub-package of the top level (segmentation, mesh, simulate, pipeline,
# _napari); mesh's job folders (mesher, model, checks, formats) are rooms of mesh, not
# packages. The top level's own modules (io, _validation, _atomic, _cli_util, ...) are
# the house's shared helpers, which every package may use.

STEPS = ("segmentation", "mesh", "simulate", "pipeline", "_napari")
#: the packages each package may import (the widgets adapt every step; the pipeline
#: chains the three; simulate solves on meshes)
MAY_IMPORT = {
    "segmentation": set(),
    "mesh": set(),
    "simulate": {"mesh"},
    "pipeline": {"segmentation", "mesh", "simulate"},
    "_napari": {"segmentation", "mesh", "simulate", "pipeline"},
}
#: private names the command line may take from its own package's modules: none (the
#: list only shrinks; test_the_cli_exceptions_are_still_needed keeps it honest)
CLI_PRIVATE_EXCEPTIONS: set[tuple[str, str]] = set()


def _package(module: str) -> str:
    """The step package holding `module` ('' for the top level's own modules)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in STEPS else ""


def _from_imports(name: str, source: str | None = None):
    """(target module, imported names) of every import in `name`, function level too."""
    is_pkg = MODULES[name].name == "__init__.py" if name in MODULES else False
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8") if source is None else source)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = name if is_pkg else name.rpartition(".")[0]
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            yield target, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, []


def _private_reach_ins(name: str, source: str | None = None) -> list[str]:
    """Imports in `name` of another package's private module or private name."""
    home, bad = _package(name), []
    for target, names in _from_imports(name, source):
        if not target.startswith(PACKAGE + ".") or _package(target) in ("", home):
            continue
        inner = target.split(".")[2:]            # below the package: must be its face
        private = [n for n in names if n.startswith("_") and not n.endswith("__")]
        if any(p.startswith("_") for p in inner) or private:
            bad.append(f"from {target} import {', '.join(names)}")
    return bad


def _layer_breaks(name: str, source: str | None = None) -> list[str]:
    home = _package(name)
    if not home:
        return []
    bad = []
    for target, names in _from_imports(name, source):
        there = _package(target) if target.startswith(PACKAGE + ".") else ""
        if there and there != home and there not in MAY_IMPORT[home]:
            bad.append(f"from {target} import {', '.join(names)}")
    return bad


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_module_imports_a_private_module_or_name_of_another_package(name):
    assert _private_reach_ins(name) == [], f"{name}: import from the package's face instead"


@pytest.mark.parametrize("name", sorted(n for n in MODULES if _package(n)))
def test_packages_import_only_the_steps_below_them(name):
    # segmentation imports neither mesh nor simulate; mesh neither segmentation nor
    # simulate; simulate only mesh; the pipeline the three steps; nothing the widgets
    assert _layer_breaks(name) == []


def test_the_layer_check_finds_a_planted_break():
    seg = f"{PACKAGE}.segmentation._segment"
    assert _layer_breaks(seg, "from ..mesh import mesh_labels") != []
    assert _layer_breaks(seg, "from ..simulate import simulate") != []
    assert _layer_breaks(f"{PACKAGE}.mesh.formats._export", "from ...simulate import x") != []
    assert _layer_breaks(f"{PACKAGE}.simulate._adapt", "from ..mesh import Mesh") == []
    assert _layer_breaks(seg, "from ..io import read_image") == []


def test_the_region_tree_is_shared_below_every_step():
    # the tree of a label image serves the mesher's leaves and segmentation's samples from
    # a truth; it lives with the house's shared helpers, so it may import no step package
    tree = f"{PACKAGE}._region_tree"
    assert {_package(m) for m in GRAPH[tree]} <= {""}
    assert tree in GRAPH[f"{PACKAGE}.segmentation._samples"]
    assert tree in GRAPH[f"{PACKAGE}.mesh.mesher._imesh"]


def test_the_private_reach_in_check_finds_a_planted_one():
    # guards the checker: reaching into mesh's rooms or taking a private name is found,
    # the face is not, and a package's own private modules are its own business
    widget = f"{PACKAGE}._napari._mesh_widget"
    assert _private_reach_ins(widget, "from ..mesh.formats._export import X") != []
    assert _private_reach_ins(widget, "from ..simulate import _adapt") != []
    assert _private_reach_ins(widget, "from ..mesh import write_mesh") == []
    assert _private_reach_ins(f"{PACKAGE}.mesh.checks._facets",
                              "from ..model._types import Mesh") == []
    assert _private_reach_ins(f"{PACKAGE}.simulate._adapt",
                              "from .._validation import as_labels") == []


def _is_cli_module(name: str) -> bool:
    return name.rpartition(".")[2] in {"cli", "_cli"}


@pytest.mark.parametrize("name", sorted(n for n in MODULES if _is_cli_module(n)))
def test_command_line_modules_call_only_public_library_functions(name):
    private = sorted(
        n for target, names in _from_imports(name) if target.startswith(PACKAGE)
        for n in names
        if n.startswith("_") and not n.endswith("__") and (name, n) not in CLI_PRIVATE_EXCEPTIONS
        and f"{target}.{n}" not in MODULES)      # `from . import _glossary` is a module
    assert private == [], f"{name} calls library internals {private}"


def test_the_cli_exceptions_are_still_needed():
    # an exception that is no longer used must be struck out, so the list only shrinks
    used = {(name, n) for name in MODULES if _is_cli_module(name)
            for _, names in _from_imports(name) for n in names}
    assert CLI_PRIVATE_EXCEPTIONS <= used


#: a string that is a mesh file's suffix, or the ending of a facet companion's name (a
#: whole file name, such as the demo's "mesh.vtu", is a name, not a format's knowledge)
_MESH_SUFFIX = re.compile(r"^(\.(vtu|vtk|msh|xdmf|h5|inp|node|ele|poly|face)|_\w*facets\.vtu)$",
                          re.IGNORECASE)
#: the format registry: the only module that may spell them
_REGISTRY = {f"{PACKAGE}.mesh._registry", f"{PACKAGE}.mesh.formats._registry"}


def _suffix_literals(name: str) -> list[str]:
    """The string constants of module `name` that spell a mesh suffix (docstrings aside)."""
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef,
                                       ast.ClassDef))
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    return [node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and id(node) not in docstrings and _MESH_SUFFIX.match(node.value)]


def test_only_the_format_registry_spells_mesh_suffixes():
    """One record per format (issue 24): a suffix literal anywhere else is knowledge of a
    format kept outside its record, which the next format would have to find."""
    spelled = {name: _suffix_literals(name) for name in MODULES
               if name not in _REGISTRY}
    assert {name: found for name, found in spelled.items() if found} == {}
    assert any(_suffix_literals(name) for name in _REGISTRY if name in MODULES)


def test_the_suffix_rule_finds_a_planted_literal(monkeypatch, tmp_path):
    planted = tmp_path / "planted.py"
    planted.write_text('"""Mentions .vtu in prose."""\nSUFFIX = ".VTU"\nEND = "_facets.vtu"\n'
                       'NAME = "mesh.vtu"\n')
    monkeypatch.setitem(MODULES, "planted", planted)
    assert _suffix_literals("planted") == [".VTU", "_facets.vtu"]
