"""The shape of the segmentation package (issue 14): small modules, no cycles, no
command-line imports in the library."""

import ast
from pathlib import Path

import napari_swa_imesh.segmentation as seg

PACKAGE = Path(seg.__file__).parent
CLI_MODULES = {"_cli", "_cli_util"}


def imports_of(path):
    """Module names imported anywhere in `path` (relative ones as written, dots stripped)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            names.add((node.module or "").split(".")[-1])
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.Import):
            names.update(a.name.split(".")[-1] for a in node.names)
    return names


def test_no_module_over_500_lines():
    sizes = {p.name: len(p.read_text().splitlines()) for p in PACKAGE.glob("*.py")}
    assert max(sizes.values()) <= 500, sizes


def test_library_modules_never_import_command_line_modules():
    for path in PACKAGE.glob("*.py"):
        if path.stem in CLI_MODULES:
            continue
        assert not imports_of(path) & CLI_MODULES, path.name


def test_the_models_do_not_import_each_other():
    assert not {"_recommended", "RecommendedModel"} & imports_of(PACKAGE / "_model.py")
    assert not {"_model", "SWAModel", "_model_io"} & imports_of(PACKAGE / "_recommended.py")


def test_no_private_names_imported_across_modules():
    for path in PACKAGE.glob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level:
                private = [a.name for a in node.names
                           if a.name.startswith("_") and not a.name.endswith("__")]
                assert not private, f"{path.name} imports {private} from {node.module}"
