"""Model files carry the package version and a format version; reading checks the format.

Format 1 files say ``format_version: 1``; a file of a newer format is refused with one
sentence (and ``swa-imesh segment --model`` exits 2); a format 0 file (written before the
number existed) still loads, its absent keys read as the defaults they meant.
"""

import json
import zipfile

import numpy as np
import pytest

import napari_swa_imesh
from napari_swa_imesh.cli import main
from napari_swa_imesh.segmentation import Samples, load_model, segment
from napari_swa_imesh.segmentation._model_io import MODEL_FORMAT_VERSION, read_model_file


def _scene(shape=(64, 64), seed=0):
    rng = np.random.default_rng(seed)
    truth = np.ones(shape, np.int32)
    truth[:, shape[1] // 2:] = 2
    img = rng.normal(0, 1, shape) * np.where(truth == 1, 1.0, 3.0) + 10
    s = Samples.from_dict({
        "materials": [{"label": 1, "name": "quiet"}, {"label": 2, "name": "rough"}],
        "boxes": [{"label": 1, "start": [0, 0], "stop": [shape[0], shape[1] // 2 - 2]},
                  {"label": 2, "start": [0, shape[1] // 2 + 2], "stop": list(shape)}]})
    return img, s


@pytest.fixture(scope="module", params=["reference", "recommended"])
def saved(request, tmp_path_factory):
    img, s = _scene()
    kw = {"scale": 2} if request.param == "reference" else {}
    model = segment(img, s, method=request.param, **kw).model
    path = model.save(tmp_path_factory.mktemp(request.param) / "m.npz")
    return request.param, model, path, img


def _rewrite(src, dst, edit):
    """Copy the model file `src` to `dst` with ``meta`` changed by ``edit(meta)``."""
    with np.load(src, allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        arrays = {k: data[k] for k in data.files if k != "meta"}
    edit(meta)
    np.savez_compressed(dst, meta=np.array(json.dumps(meta)), **arrays)
    return dst


def test_the_file_says_its_format_and_the_package_version(saved):
    _, _, path, _ = saved
    meta, _ = read_model_file(path)
    assert meta["format_version"] == MODEL_FORMAT_VERSION == 1
    assert meta["version"] == napari_swa_imesh.__version__


def test_round_trip_predicts_the_same_labels(saved):
    method, model, path, img = saved
    again = load_model(path)
    assert again.method == model.method == method
    np.testing.assert_array_equal(again.predict(img), model.predict(img))
    # saved again, the file holds the same meta (nothing lost or added by a load)
    second = again.save(path.with_name("again.npz"))
    assert read_model_file(second)[0] == read_model_file(path)[0]


@pytest.mark.parametrize("newer", [MODEL_FORMAT_VERSION + 1, 99])
def test_a_newer_format_is_refused_with_one_sentence(saved, tmp_path, newer):
    _, _, path, _ = saved
    bad = _rewrite(path, tmp_path / "new.npz", lambda m: m.update(format_version=newer))
    with pytest.raises(ValueError, match=rf"of format {newer} .*update napari-swa-imesh\.$"):
        load_model(bad)


@pytest.mark.parametrize("value", ["1", 1.5, -1, True, None])
def test_a_format_version_that_is_not_a_whole_number_is_damage(saved, tmp_path, value):
    _, _, path, _ = saved
    bad = _rewrite(path, tmp_path / "odd.npz", lambda m: m.update(format_version=value))
    with pytest.raises(ValueError, match="not a swa-imesh model file .*not a whole number"):
        load_model(bad)


def test_a_format_1_file_without_its_method_is_damaged(saved, tmp_path):
    _, _, path, _ = saved
    bad = _rewrite(path, tmp_path / "nomethod.npz", lambda m: m.pop("method"))
    with pytest.raises(ValueError, match="damaged or incomplete .*no method"):
        load_model(bad)


def test_a_format_0_file_still_loads_with_the_defaults_its_gaps_meant(saved, tmp_path):
    method, model, path, img = saved

    def as_format_0(meta):
        del meta["format_version"]
        if method == "reference":
            del meta["method"]          # format 0 reference files had no method
        else:
            meta.pop("coherence", None)

    old = _rewrite(path, tmp_path / "old.npz", as_format_0)
    again = load_model(old)
    assert again.method == method
    if method == "recommended":
        assert again.coherence is False
    else:
        np.testing.assert_array_equal(again.predict(img), model.predict(img))


def test_the_cli_exits_2_on_a_newer_format(saved, tmp_path, capsys):
    _, _, path, img = saved
    bad = _rewrite(path, tmp_path / "new.npz",
                   lambda m: m.update(format_version=MODEL_FORMAT_VERSION + 1))
    np.save(tmp_path / "img.npy", img)
    code = main(["segment", str(tmp_path / "img.npy"), "--model", str(bad),
                 "-o", str(tmp_path / "lab.npy")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"of format {MODEL_FORMAT_VERSION + 1}" in err and "update napari-swa-imesh" in err
    assert not (tmp_path / "lab.npy").exists()
    assert zipfile.is_zipfile(bad)
