"""Paths of one kind need an extra; without it the command says which, and exits 2.

Each module of ``_extras.EXTRAS`` is blocked the way a missing install looks to Python
(``sys.modules[name] = None`` makes ``import name`` raise ImportError). The command then
exits 2 with one sentence naming ``pip install "napari-swa-imesh[<extra>]"`` and writes
nothing; the paths every user takes (segment in memory, RES of a ``.npy``, mesh to
``.vtu``) run without any extra.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from napari_swa_imesh._extras import EXTRAS, MissingExtra, require
from napari_swa_imesh.cli import main
from napari_swa_imesh.segmentation import Samples, save_samples

ALL = tuple(EXTRAS)


def _block(monkeypatch, *modules):
    for name in modules:
        monkeypatch.setitem(sys.modules, name, None)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("extras")
    rng = np.random.default_rng(0)
    truth = np.ones((64, 64), np.int32)
    truth[:, 32:] = 2
    img = rng.normal(0, 1, truth.shape) * np.where(truth == 1, 1.0, 3.0) + 10
    np.save(folder / "img.npy", img)
    np.save(folder / "labels.npy", truth)
    save_samples(Samples.from_dict({
        "materials": [{"label": 1, "name": "quiet"}, {"label": 2, "name": "rough"}],
        "boxes": [{"label": 1, "start": [0, 0], "stop": [64, 28]},
                  {"label": 2, "start": [0, 36], "stop": [64, 64]}]}), folder / "s.json")
    assert main(["segment", str(folder / "img.npy"), "--samples", str(folder / "s.json"),
                 "--method", "reference", "--scale", "2", "--model-out",
                 str(folder / "m.npz"), "-o", str(folder / "lab.npy")]) == 0
    (folder / "cohort").mkdir()
    np.save(folder / "cohort" / "a.npy", img)
    return folder


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def test_require_names_the_extra_and_is_a_value_and_an_import_error(monkeypatch):
    _block(monkeypatch, "zarr")
    with pytest.raises(MissingExtra, match=r'^reading x needs zarr, which is not installed; '
                       r'install it with pip install "napari-swa-imesh\[scale\]"\.$') as caught:
        require("dask", "zarr", purpose="reading x")
    assert isinstance(caught.value, ValueError) and isinstance(caught.value, ImportError)
    require("numpy" if "numpy" in EXTRAS else "dask", purpose="nothing missing")


@pytest.mark.parametrize("blocked,argv,extra", [
    ("zarr", ["segment", "{d}/img.npy", "--model", "{d}/m.npz", "-o", "{o}/lab.zarr"],
     "scale"),
    ("dask", ["segment", "{d}/img.npy", "--model", "{d}/m.npz", "--memory", "1GB",
              "-o", "{o}/lab.npy"], "scale"),
    ("dask", ["segment", "{d}/img.npy", "--samples", "{d}/s.json", "-o", "{o}/lab.zarr"],
     "scale"),
    ("distributed", ["batch", "--model", "{d}/m.npz", "-o", "{o}", "{d}/cohort"], "scale"),
    ("zarr", ["res", "{o}/missing.zarr", "--samples", "{d}/s.json"], "scale"),
    ("h5py", ["mesh", "{d}/labels.npy", "-o", "{o}/m.xdmf"], "xdmf"),
    ("h5py", ["simulate", "{d}/labels.npy", "--conductivity", "1=1", "2=10",
              "-o", "{o}/field.xdmf"], "xdmf"),
])
def test_a_path_without_its_extra_exits_2_naming_it(scene, tmp_path, capsys, monkeypatch,
                                                    blocked, argv, extra):
    out = tmp_path / "out"
    out.mkdir()
    _block(monkeypatch, blocked)
    code, err = _run(capsys, *(a.format(d=scene, o=out) for a in argv))
    assert code == 2, err
    assert f'needs {blocked}, which is not installed' in err
    assert f'pip install "napari-swa-imesh[{extra}]"' in err
    assert err.count("\n") == 1                       # one sentence, no traceback
    assert list(out.iterdir()) == []


def test_the_paths_every_user_takes_need_no_extra(scene, tmp_path, capsys, monkeypatch):
    _block(monkeypatch, *ALL)
    code, err = _run(capsys, "segment", scene / "img.npy", "--samples", scene / "s.json",
                     "--method", "reference", "--scale", 2, "-o", tmp_path / "lab.npy")
    assert code == 0, err
    np.testing.assert_array_equal(np.load(tmp_path / "lab.npy"), np.load(scene / "lab.npy"))
    code, err = _run(capsys, "segment", scene / "img.npy", "--model", scene / "m.npz",
                     "-o", tmp_path / "lab2.npy")
    assert code == 0, err
    code, err = _run(capsys, "res", scene / "img.npy", "--samples", scene / "s.json")
    assert code == 0, err
    code, err = _run(capsys, "mesh", scene / "labels.npy", "-o", tmp_path / "m.vtu")
    assert code == 0, err
    code, err = _run(capsys, "simulate", scene / "labels.npy", "--conductivity", "1=1",
                     "2=10", "-o", tmp_path / "field.vtu")
    assert code == 0, err


@pytest.mark.slow
def test_the_readme_first_command_runs_the_whole_demo_without_extras(tmp_path):
    import subprocess

    block = (f"import sys\nfor m in {ALL!r}: sys.modules[m] = None\n"
             "from napari_swa_imesh.cli import main\nsys.exit(main(['demo', '--json']))")
    done = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True,
                          text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "swa-imesh-demo" / "field.vtu").is_file()
