"""``--coarsen K`` that leaves only excluded labels is refused in one sentence (issue 22)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import mesh_labels
from napari_swa_imesh.mesh.mesher._coarsen import coarsen_labels


@st.composite
def cases(draw):
    ndim = draw(st.sampled_from([2, 3]))
    shape = tuple(draw(st.lists(st.integers(1, 7), min_size=ndim, max_size=ndim)))
    values = draw(st.lists(st.integers(0, 3), min_size=int(np.prod(shape)),
                           max_size=int(np.prod(shape))))
    labels = np.array(values, np.uint8).reshape(shape)
    present = sorted(set(values))
    exclude = draw(st.lists(st.sampled_from(present), max_size=len(present), unique=True))
    return labels, exclude, draw(st.integers(1, 3))


@pytest.mark.filterwarnings("ignore:coarsening by")
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
@example((np.array([[0, 0], [0, 1]], np.uint8), [0], 1))       # the refusal, for certain
@example((np.array([[0, 1], [1, 1]], np.uint8), [0], 1))
def test_coarsening_meshes_or_refuses_when_only_excluded_labels_remain(case):
    labels, exclude, level = case
    coarse, _ = coarsen_labels(labels, level)
    left = set(np.unique(coarse).tolist()) - set(exclude)
    assume(not set(np.unique(labels).tolist()) <= set(exclude))   # refused at the door
    if not left:
        with pytest.raises(ValueError, match=r"coarsening to blocks of \d+ voxels per axis "
                                             r"leaves only excluded labels"):
            mesh_labels(labels, exclude=exclude, coarsen=level)
    else:
        mesh = mesh_labels(labels, exclude=exclude, coarsen=level)
        assert set(np.unique(mesh.material).tolist()) == left


def test_the_command_line_says_it_in_one_sentence(tmp_path, capsys):
    labels = np.zeros((8, 8, 8), np.uint8)
    labels[0, 0, 0] = 1
    np.save(tmp_path / "l.npy", labels)
    code = main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.vtu"),
                 "--coarsen", "2", "--exclude", "0"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "leaves only excluded labels ([0])" in err and "lower --coarsen" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy"]
