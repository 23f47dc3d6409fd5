"""A piece's own checks (issue 27): the chain of its facets and its volumes, from the
template tables, catch a doubled element, a hole and a turned element."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.mesh.blocks import _core as bk
from napari_swa_imesh.mesh.blocks import _piece as pc


def _volume():
    lab = np.zeros((16, 16, 16), np.int64)
    lab[2:14, 3:12, 1:15] = 1
    lab[5:9, 5:9, 5:9] = 2
    lab[np.random.default_rng(0).random(lab.shape) < 0.02] = 3
    return lab


def _middle_piece(lab, monkeypatch=None, edit=None):
    plan = bk.plan_blocks(lab.shape, 8)
    mixed = {i: bk.mixed_grids(bk._window_labels(plan, i, lab[plan.window(i)[0]]), plan.top)
             for i in plan.blocks()}
    split = bk.balance_grids(plan, mixed)
    if edit is not None:
        real = bk.template_mesh

        def edited(*args, **kw):
            pts, cells, leaf_of, tid, *rest = real(*args, **kw)
            return (pts, *edit(cells, leaf_of, tid), *rest)

        monkeypatch.setattr(bk, "template_mesh", edited)
    index = (1, 0, 1)
    return bk.mesh_block(plan, index, lab[plan.window(index)[0]],
                         bk.block_slices(plan, split, index), exclude=(0,), present=[1, 2, 3])


def test_a_clean_piece_has_no_problem():
    piece = _middle_piece(_volume())
    assert len(piece.cells) and piece.problems == []


@pytest.mark.parametrize("edit, words", [
    # an element twice: its facets seen twice from one side
    (lambda c, lf, t: (np.vstack([c, c[:1]]), np.append(lf, lf[0]), np.append(t, t[0])),
     "do not pair up"),
    # an element missing: a hole
    (lambda c, lf, t: (c[1:], lf[1:], t[1:]), "do not pair up"),
    # an element turned inside out
    (lambda c, lf, t: (np.vstack([c[:1, [1, 0, 2, 3]], c[1:]]), lf, t), "positive volume"),
])
def test_a_broken_piece_is_caught(monkeypatch, edit, words):
    piece = _middle_piece(_volume(), monkeypatch, edit)
    assert any(words in p for p in piece.problems), piece.problems


def test_face_tables_agree_with_the_template_coordinates():
    from napari_swa_imesh.mesh.formats._common import FACE_CORNERS
    from napari_swa_imesh.mesh.mesher import _templates_luts as luts

    for d in (2, 3):
        on_face, low2 = pc.face_tables(d)
        tpl = luts.TEMPLATES[d]
        for k in range(d + 1):
            corners = tpl[:, FACE_CORNERS[d][k]]
            for t in range(len(tpl)):
                bit = on_face[t, k]
                flat = [a for a in range(d) if np.ptp(corners[t, :, a]) == 0
                        and corners[t, 0, a] in (0.0, 1.0)]
                assert (bit < 0) == (not flat)
                if bit >= 0:
                    assert bit >> 1 == flat[0] and (bit & 1) == corners[t, 0, flat[0]]
            assert np.array_equal(low2[:, k], 2 * corners.min(axis=1))
