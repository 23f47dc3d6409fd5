import json

import numpy as np
import pytest

from napari_swa_imesh.segmentation._samples import (
    Samples,
    load_samples,
    samples_from_truth,
    save_samples,
)

SCHEMA = {"materials": [{"label": 1, "name": "brick"}, {"label": 2, "name": "grass"}],
          "boxes": [{"label": 1, "start": [0, 0], "stop": [10, 12]},
                    {"label": 2, "start": [5, 12], "stop": [20, 30]}]}


def test_json_round_trip(tmp_path):
    s = Samples.from_dict(SCHEMA)
    p = save_samples(s, tmp_path / "s.json")
    assert json.loads(p.read_text()) == SCHEMA
    t = load_samples(p)
    assert t == s and t.name_of(2) == "grass" and t.boxes[1].shape == (15, 18)


def test_no_overwrite_without_force(tmp_path):
    p = tmp_path / "s.json"
    p.write_text("user data")
    with pytest.raises(FileExistsError, match="--force"):
        save_samples(Samples.from_dict(SCHEMA), p)
    assert p.read_text() == "user data"
    save_samples(Samples.from_dict(SCHEMA), p, force=True)
    assert load_samples(p).labels == [1, 2]


def test_box_outside_image_and_bad_boxes():
    s = Samples.from_dict(SCHEMA)
    with pytest.raises(ValueError, match="outside the image"):
        s.check((20, 25))
    with pytest.raises(ValueError, match="axes"):
        s.check((20, 30, 4))
    s.check((20, 30))
    with pytest.raises(ValueError, match="empty"):
        Samples.from_dict({"boxes": [{"label": 1, "start": [3, 3], "stop": [3, 9]}]})
    with pytest.raises(ValueError, match="background"):
        Samples.from_dict({"boxes": [{"label": 0, "start": [0, 0], "stop": [3, 9]}]})
    with pytest.raises(ValueError, match="'label', 'start' and 'stop'"):
        Samples.from_dict({"boxes": [{"start": [0, 0], "stop": [3, 9]}]})


def test_unreadable_samples_file(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_samples(p)
    with pytest.raises(FileNotFoundError, match="no samples file"):
        load_samples(tmp_path / "missing.json")


@pytest.mark.parametrize("shape", [(40, 37), (20, 18, 23)])
def test_samples_from_truth_are_homogeneous_and_largest(shape):
    rng = np.random.default_rng(0)
    truth = np.ones(shape, int)
    truth[tuple(slice(n // 3, n) for n in shape)] = 2
    truth[tuple(slice(0, 3) for _ in shape)] = 3
    noise = rng.random(shape) < 0.01
    truth[noise] = 0  # background specks give no samples
    s = samples_from_truth(truth, per_material=3)
    assert s.labels == [1, 2, 3]
    for b in s.boxes:
        region = truth[b.slices]
        assert (region == b.label).all()
        side = b.stop[0] - b.start[0]
        assert side & (side - 1) == 0   # dyadic blocks of the tree
    # the boxes of a material are no smaller than any other leaf block of that material
    for label in (1, 2):
        sides = [b.shape[0] for b in s.boxes_of(label)]
        assert sides == sorted(sides, reverse=True)


def test_samples_from_truth_prefers_blocks_big_enough_for_scale():
    truth = np.ones((64, 64), int)
    truth[:32, :32] = 2
    truth[40:41, 40:41] = 2     # a 1-pixel block of material 2 must not be picked at scale 3
    s = samples_from_truth(truth, scale=3, per_material=5)
    assert all(b.shape[0] >= 16 for b in s.boxes)
