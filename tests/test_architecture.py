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
    a, b = f"{PACKAGE}.io", f"{PACKAGE}.mesh.mesher._tree"
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
