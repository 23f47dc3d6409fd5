"""The plugin installed the way napari's plugin manager installs it, and used.

A fresh virtual environment (no system site-packages) gets napari and a Qt binding, then
``pip install <this source>`` with no extras (a wheel built from a copy of the source tree,
not an editable install); ``napari_smoke.py`` then docks every widget of the manifest
through napari's plugin machinery and runs the workflow on the sample data. Reported case:
with the widgets' imports (napari-matplotlib among them) in an extra, every widget failed to
import (``No module named 'napari_matplotlib'``); this test failed the same way when
napari-matplotlib was taken out of the base dependencies.

Needs a package index (or pip's cache) and an X display: pytest-xvfb's, or ``xvfb-run``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SMOKE = Path(__file__).with_name("napari_smoke.py")
# what a user has before the plugin: napari with the Qt binding of its own extra
NAPARI = "napari[pyqt6]"

pytestmark = pytest.mark.install


def _run(command, *, env, timeout):
    done = subprocess.run(command, env=env, timeout=timeout, capture_output=True, text=True)
    assert done.returncode == 0, (f"{' '.join(map(str, command))} exited {done.returncode}:\n"
                                  f"{done.stdout[-3000:]}\n{done.stderr[-5000:]}")
    return done.stdout


def _source_copy(destination: Path) -> Path:
    """The files a wheel is built from, copied so the build leaves the checkout untouched."""
    destination.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, destination / name)
    shutil.copytree(ROOT / "src", destination / "src",
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.pyc"))
    return destination


def test_plain_install_into_a_napari_environment_docks_and_runs(tmp_path):
    start = time.monotonic()
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP")}
    env["NAPARI_CONFIG"] = str(tmp_path / "napari-settings.yaml")   # the user's stay as they are
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], env=env, timeout=120)
    python = venv / "bin" / "python"
    pip = [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    _run(pip + [NAPARI], env=env, timeout=900)
    _run(pip + [str(_source_copy(tmp_path / "source"))], env=env, timeout=900)
    listed = _run([str(python), "-m", "pip", "list", "--format=freeze"], env=env, timeout=60)
    assert "napari-swa-imesh==" in listed          # a regular install, not an editable one

    command = [str(python), str(SMOKE)]
    if not env.get("DISPLAY"):
        if shutil.which("xvfb-run") is None:
            pytest.fail("no X display and no xvfb-run: run .ci/install (it installs xvfb)")
        command = ["xvfb-run", "-a", "-s", "-screen 0 1280x800x24"] + command
    # from an empty directory, so nothing of the checkout can shadow the installed wheel
    workdir = tmp_path / "run"
    workdir.mkdir()
    done = subprocess.run(command, env=env, cwd=workdir, timeout=600, capture_output=True,
                          text=True)
    print(done.stdout)
    print(f"install check: {time.monotonic() - start:.0f} s")
    assert done.returncode == 0 and "SMOKE OK" in done.stdout, done.stderr[-5000:]
    assert done.stdout.count("docked ") == 6
