"""The scale story: the suggested RES is one the classifier trains at, and `res` explains
every blank of its table (issue 23, sec. 3)."""

import json
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from napari_swa_imesh.cli import main
from napari_swa_imesh.segmentation import segment
from napari_swa_imesh.segmentation._res import res_statistics, trainable_scale
from napari_swa_imesh.segmentation._samples import Samples


def narrow_box_scene():
    """Two materials; 'csf' has one 64x4 box: 16 full tiles of 4 px (scale 2 would have
    the tiles), but no window of 5 px fits, so the recommended method trains up to 1."""
    rng = np.random.default_rng(0)
    img = np.concatenate([rng.normal(0, 1, (64, 32)), rng.normal(3, 1, (64, 32))], 1)
    samples = Samples.from_dict({
        "materials": [{"label": 1, "name": "a"}, {"label": 2, "name": "csf"}],
        "boxes": [{"label": 1, "start": [0, 0], "stop": [64, 32]},
                  {"label": 2, "start": [0, 40], "stop": [64, 44]}]})
    return img, samples


def test_suggested_res_trains_without_being_lowered():
    img, s = narrow_box_scene()
    st = res_statistics(img, s)
    # what the statistics alone allow (the reference, tiles only) is higher
    assert res_statistics(img, s, method="reference").suggested_scale == 2
    assert st.suggested_scale == 1
    # the box that limits it is named once, with what to do
    assert st.reason.count("box #1") == 1 and "'csf'" in st.reason
    assert "enlarge it to at least 5 px" in st.reason
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # segment must not lower the scale again
        result = segment(img, s)
    assert result.model.scores["top_scale"] == st.suggested_scale
    assert result.res.suggested_scale == st.suggested_scale


def test_reference_suggestion_is_trainable_by_the_reference_method():
    img, s = narrow_box_scene()
    st = res_statistics(img, s, method="reference")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = segment(img, s, method="reference")
    assert result.scale == st.suggested_scale


@pytest.mark.parametrize("method", ["recommended", "reference"])
def test_trainable_scale_agrees_with_the_limits_segment_applies(method):
    s = Samples.from_dict({"boxes": [{"label": 1, "start": [0, 0], "stop": [64, 64]},
                                     {"label": 2, "start": [0, 0], "stop": [8, 40]}]})
    top, limit = trainable_scale(s, 2, 5, method=method)
    assert limit is not None and "box #1" in limit
    assert trainable_scale(s, 2, top, method=method) == (top, None)


def test_unknown_method_is_refused():
    img, s = narrow_box_scene()
    with pytest.raises(ValueError, match="method must be one of recommended, reference"):
        res_statistics(img, s, method="fast")


@pytest.fixture
def scene(tmp_path):
    img, s = narrow_box_scene()
    np.save(tmp_path / "img.npy", img)
    (tmp_path / "s.json").write_text(json.dumps(
        {"materials": [{"label": m.label, "name": m.name} for m in s.materials],
         "boxes": [{"label": b.label, "start": list(b.start), "stop": list(b.stop)}
                   for b in s.boxes]}))
    return tmp_path


def test_cli_res_suggests_what_segment_then_uses(scene, capsys):
    assert main(["res", str(scene / "img.npy"), "--samples", str(scene / "s.json")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("suggested RES: 1 ")
    assert main(["segment", str(scene / "img.npy"), "--samples", str(scene / "s.json"),
                 "-o", str(scene / "l.npy"), "--json"]) == 0
    captured = capsys.readouterr()
    assert "warning" not in captured.err
    report = json.loads(captured.out)
    assert report["suggested_scale"] == 1
    assert main(["res", str(scene / "img.npy"), "--samples", str(scene / "s.json"),
                 "--method", "reference"]) == 0
    assert capsys.readouterr().out.startswith("suggested RES: 2 ")


def test_cli_res_marks_and_explains_scales_without_statistics(scene, capsys):
    assert main(["res", str(scene / "img.npy"), "--samples", str(scene / "s.json")]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out.lower()
    rows = [line.split() for line in out.splitlines() if line.startswith("  ")
            and line.split()[0].isdigit()]
    short = [r for r in rows if int(r[1]) < 4]           # fewer than 2^d = 4 tiles
    assert short and all(r[2:] == ["-", "-", "-", "(*)"] for r in short)
    assert all("(*)" not in r for r in rows if int(r[1]) >= 4)
    assert "(*) fewer than 2^d = 4 full tiles" in out


def test_cli_glossary_defines_eps_m_as_the_spec_does(capsys):
    assert main(["glossary", "eps_m"]) == 0
    assert "-#F x eps_l / 100" in capsys.readouterr().out
    assert main(["glossary", "nope"]) == 2
    assert "not in the glossary" in capsys.readouterr().err


@settings(max_examples=40, deadline=None)
@given(sides=st.lists(st.tuples(st.integers(2, 40), st.integers(2, 40)), min_size=2,
                      max_size=4),
       method=st.sampled_from(["recommended", "reference"]))
def test_the_suggestion_always_trains(sides, method):
    """Whatever the boxes, the suggested RES is one the method trains at unchanged."""
    rng = np.random.default_rng(len(sides))
    img = rng.gamma(2.0, 1.0, (48, 48 * len(sides)))
    img += np.repeat(np.arange(len(sides)) * 3.0, 48)[None, :]
    boxes = [{"label": i + 1, "start": [0, 48 * i], "stop": [r, 48 * i + c]}
             for i, (r, c) in enumerate(sides)]
    s = Samples.from_dict({"boxes": boxes})
    st_ = res_statistics(img, s, method=method)
    if st_.suggested_scale is not None:
        assert trainable_scale(s, 2, st_.suggested_scale, method=method) == (
            st_.suggested_scale, None)
