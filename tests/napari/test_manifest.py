"""The plugin manifest: discovered by npe2, valid, importable, and shipped in the wheel."""

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_npe2_discovers_and_validates_the_manifest():
    from npe2 import PluginManager, PluginManifest

    pm = PluginManager()
    pm.discover()
    manifest = pm.get_manifest("napari-swa-imesh")
    assert manifest.name == "napari-swa-imesh"
    # every python_name imports and resolves (what `npe2 validate --imports` checks)
    manifest.validate_imports()
    contributions = manifest.contributions
    widget_commands = {w.command for w in contributions.widgets}
    assert {c.rsplit(".", 1)[1] for c in widget_commands} == {
        f"{w}_widget" for w in ("workflow", "samples", "res", "classify", "mesh", "simulate")}
    segment_menu = [item.command for item in contributions.menus["napari/layers/segment"]]
    assert segment_menu == [f"napari-swa-imesh.{w}_widget"
                            for w in ("workflow", "samples", "res", "classify")]
    measure_menu = [item.command for item in contributions.menus["napari/layers/measure"]]
    assert measure_menu == ["napari-swa-imesh.mesh_widget", "napari-swa-imesh.simulate_widget"]
    readers = {r.command.rsplit(".", 1)[1]: set(r.filename_patterns)
               for r in contributions.readers}
    assert readers["get_tiff_reader"] == {"*.tif", "*.tiff"}
    assert {"*.vtu", "*.msh"} <= readers["get_mesh_reader"]
    assert {s.key for s in contributions.sample_data} == {"texture_mosaic", "tissue_phantom"}
    (writer,) = contributions.writers
    assert writer.layer_types == ["surface"]
    assert {".vtu", ".msh", ".xdmf", ".inp", ".node"} <= set(writer.filename_extensions)
    # the file in the package is the one the entry point names, and it validates on its own
    assert PluginManifest.from_file(ROOT / "src/napari_swa_imesh/napari.yaml").name == \
        manifest.name


def test_top_level_manifest_is_a_symlink_to_the_packaged_one():
    top = ROOT / "napari.yaml"
    assert top.is_symlink()
    assert top.resolve() == (ROOT / "src/napari_swa_imesh/napari.yaml").resolve()


def test_wheel_contains_the_manifest(tmp_path):
    import importlib.util

    import setuptools

    has_bdist_wheel = importlib.util.find_spec("wheel") is not None or \
        tuple(int(v) for v in setuptools.__version__.split(".")[:2]) >= (70, 1)
    if not has_bdist_wheel:
        pytest.skip("building a wheel without isolation needs the 'wheel' package "
                    "(or setuptools >= 70.1)")
    # build from a copy: building in place would leave build/ and egg-info behind
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".git", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", "docs",
        "benchmarks", "reference", "tests"))
    out = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(tmp_path / "dist"), str(src)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    (wheel,) = (tmp_path / "dist").glob("*.whl")
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        assert "napari_swa_imesh/napari.yaml" in names
        entry_points = next(n for n in names if n.endswith("entry_points.txt"))
        assert "napari_swa_imesh:napari.yaml" in zf.read(entry_points).decode()
        assert zf.read("napari_swa_imesh/napari.yaml").startswith(b"name: napari-swa-imesh")


def test_only_the_plugin_package_imports_gui_modules():
    """napari, Qt and magicgui appear in import lines of the _napari package only."""
    import re

    gui = re.compile(r"^\s*(from|import)\s+(napari|qtpy|PyQt\d|PySide\d|magicgui|vispy)\b",
                     re.MULTILINE)
    package = ROOT / "src/napari_swa_imesh"
    offenders = [p.relative_to(package) for p in package.rglob("*.py")
                 if "_napari" not in p.parts and gui.search(p.read_text())]
    assert offenders == []
    assert any(gui.search(p.read_text()) for p in (package / "_napari").glob("*.py"))
