"""One meshing plan (``plan_mesh`` -> ``MeshPlan``) that ``mesh_labels`` and the command
line both run: checked at the door, progress step by step, the same mesh."""

from __future__ import annotations

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import MeshPlan, mesh_labels, plan_mesh, read_mesh


def _labels(shape=(8, 7, 6), seed=0):
    return np.random.default_rng(seed).integers(0, 3, shape).astype(np.uint8)


def _same(a, b):
    assert np.array_equal(a.points, b.points) and np.array_equal(a.cells, b.cells)
    assert np.array_equal(a.material, b.material) and a.recipe == b.recipe
    assert a.cell_data.keys() == b.cell_data.keys()


@pytest.mark.parametrize("options", [{}, {"exclude": [0], "spacing": (2.5, 1, 1)},
                                     {"coarsen": 1}, {"refine": 1, "periodic": True},
                                     {"method": "delaunay"}])
def test_the_plan_gives_mesh_labels_own_mesh(options):
    labels = _labels()
    if options.get("method"):
        labels = labels[..., 0]
    plan = plan_mesh(labels, **options)
    assert isinstance(plan, MeshPlan)
    steps = plan.steps()
    seen = []
    while True:
        try:
            seen.append(next(steps))
        except StopIteration as done:
            meshed = done.value
            break
    totals = {t for _, t, _ in seen}
    assert len(totals) == 1 and [d for d, _, _ in seen] == list(range(len(seen)))
    assert len(seen) == totals.pop()
    _same(meshed.mesh, mesh_labels(labels, **options))
    assert meshed.labels.shape == labels.shape
    if options.get("method") == "delaunay":
        assert "checks" in meshed.mesh.info
    with pytest.raises(ValueError, match="has run already"):
        plan.run()                                # it let go of the labels
    assert plan.labels is None


@pytest.mark.parametrize(("options", "match"), [
    ({"method": "qhull"}, "method must be one of"),
    ({"refine": 9}, "refine"),
    ({"spacing": 1.0, "affine": np.eye(4)}, "give spacing or affine, not both"),
    ({"method": "delaunay", "periodic": True}, "periodic meshes need the template method"),
    ({"exclude": [0, 1, 2]}, "every pixel is excluded"),
])
def test_the_plan_refuses_before_any_meshing(monkeypatch, options, match):
    from napari_swa_imesh.mesh.mesher import _imesh

    monkeypatch.setattr(_imesh, "_mesh_labels", lambda *a, **k: pytest.fail("meshed"))
    with pytest.raises(ValueError, match=match):
        plan_mesh(_labels(), **options)


def test_the_command_line_runs_the_plan(tmp_path, capsys, monkeypatch):
    labels = _labels()
    np.save(tmp_path / "l.npy", labels)
    ran = []
    real_run = MeshPlan.run

    def run(self, **options):
        ran.append(options)
        return real_run(self, **options)

    monkeypatch.setattr(MeshPlan, "run", run)
    code = main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.vtu"),
                 "--exclude", "0", "--coarsen", "1"])
    assert code == 0, capsys.readouterr().err
    assert ran == [{"report_checks": False}]      # its checks run beside the writer
    written = read_mesh(tmp_path / "m.vtu")
    assert len(written.cells) == mesh_labels(labels, exclude=[0], coarsen=1).n_cells
