import json

import numpy as np
import pytest

from napari_swa_imesh.io import read_image, write_labels
from napari_swa_imesh.segmentation import Samples, save_samples
from swa_cli_helpers import run


@pytest.fixture()
def scene(tmp_path):
    rng = np.random.default_rng(0)
    truth = np.ones((64, 80), np.int32)
    truth[:, 40:] = 2
    img = (rng.normal(100, 5, truth.shape) * np.where(truth == 1, 1, 1)
           + rng.normal(0, 1, truth.shape) * np.where(truth == 1, 2, 20)).clip(0, 255)
    np.save(tmp_path / "img.npy", img)
    write_labels(tmp_path / "truth.tif", truth)
    save_samples(Samples.from_dict({
        "materials": [{"label": 1, "name": "calm"}, {"label": 2, "name": "busy"}],
        "boxes": [{"label": 1, "start": [0, 0], "stop": [64, 36]},
                  {"label": 2, "start": [0, 44], "stop": [64, 80]}]}), tmp_path / "s.json")
    return tmp_path


def test_res_segment_apply_evaluate(scene, capsys):
    code, out, _ = run(capsys, "res", scene / "img.npy", "--samples", scene / "s.json",
                       "--plot", scene / "res.png", "--json")
    assert code == 0
    res = json.loads(out)
    assert res["suggested_scale"] is not None and (scene / "res.png").stat().st_size > 0
    code, out, _ = run(capsys, "segment", scene / "img.npy", "--samples", scene / "s.json",
                       "--method", "reference", "--scale", 2, "--model-out", scene / "m.npz",
                       "--signatures",
                       scene / "sig.csv", "--truth", scene / "truth.tif",
                       "-o", scene / "lab.tif", "--json")
    assert code == 0
    seg = json.loads(out)
    assert seg["scale"] == 2 and seg["mean_dice"] > 0.9 and "classify" in seg["seconds"]
    labels, _ = read_image(scene / "lab.tif")
    assert labels.shape == (64, 80)
    assert (scene / "sig.csv").read_text().startswith("label,name,tiles,mean_mean")
    code, out, _ = run(capsys, "segment", scene / "img.npy", "--model", scene / "m.npz",
                       "-o", scene / "lab2.npy", "--json")
    assert code == 0
    np.testing.assert_array_equal(np.load(scene / "lab2.npy"), labels)
    code, out, _ = run(capsys, "evaluate", scene / "lab2.npy", "--truth", scene / "truth.tif",
                       "--json")
    assert code == 0 and json.loads(out)["mean_dice"] == pytest.approx(seg["mean_dice"])


def test_segment_default_scale_and_text_output(scene, capsys):
    code, out, _ = run(capsys, "segment", scene / "img.npy", "--samples", scene / "s.json",
                       "-o", scene / "lab.npy")
    assert code == 0 and "eps_l" in out and "labels written" in out
    assert out.startswith("recommended method: scales") and "pixels labelled per scale" in out


def test_samples_from_truth(scene, capsys):
    code, out, _ = run(capsys, "samples-from-truth", scene / "truth.tif", "--per-material", 2,
                       "-o", scene / "auto.json", "--json")
    assert code == 0
    data = json.loads((scene / "auto.json").read_text())
    assert {b["label"] for b in data["boxes"]} == {1, 2}


def test_refuses_to_overwrite(scene, capsys):
    (scene / "lab.npy").write_bytes(b"precious")
    code, _, err = run(capsys, "segment", scene / "img.npy", "--samples", scene / "s.json",
                       "-o", scene / "lab.npy")
    assert code == 2 and "--force" in err
    assert (scene / "lab.npy").read_bytes() == b"precious"


@pytest.mark.parametrize("make,args,message", [
    ("rgb", ["--samples", "s.json", "--scale", "2"], "RGB"),
    ("nan", ["--samples", "s.json", "--scale", "2"], "NaN"),
    ("img", ["--samples", "far.json", "--scale", "2"], "outside the image"),
    ("img", ["--samples", "s.json", "--method", "reference", "--scale", "6"], "full tile"),
    ("img", ["--samples", "s.json", "--method", "reference", "--features", "F12"], "F1"),
    ("img", ["--samples", "s.json", "--features", "F1"], "add --method reference"),
    ("img", ["--samples", "s.json", "--scale", "9"], "max_scale must be 0..8"),
    ("missing", ["--samples", "s.json"], "no image file"),
    ("vol", ["--samples", "s.json", "--scale", "1"], "axes"),
])
def test_bad_input_is_one_clear_line(scene, capsys, make, args, message):
    name = {"rgb": "rgb.png", "nan": "nan.npy", "img": "img.npy", "missing": "nope.tif",
            "vol": "vol.npy"}[make]
    if make == "rgb":
        import imageio.v3 as iio

        iio.imwrite(scene / name, np.zeros((64, 80, 3), np.uint8))
    elif make == "nan":
        a = np.ones((64, 80))
        a[3, 3] = np.nan
        np.save(scene / name, a)
    elif make == "vol":
        np.save(scene / name, np.ones((4, 64, 80)))
    save_samples(Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [99, 9]}]}),
                 scene / "far.json", force=True)
    argv = ["segment", scene / name] + [scene / a if a.endswith(".json") else a for a in args]
    code, out, err = run(capsys, *argv, "-o", scene / "o.npy")
    assert code == 2
    assert message in err and "Traceback" not in err and err.count("\n") == 1
