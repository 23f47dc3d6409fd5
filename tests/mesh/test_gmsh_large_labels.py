"""``.msh`` with labels no Gmsh tag holds (issue 22): ranks as tags, names keep the labels."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from gmsh_helpers import gmsh_reads
from test_export import grid_mesh

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import read_mesh, write_mesh
from napari_swa_imesh.mesh.formats._gmsh import gmsh_tags

BIG = 2**40 + 3


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("labels", [[0, 3, BIG], [-5, 0, 7], [2**31 - 1, 0, 1]])
def test_labels_beyond_gmsh_tags_are_ranked_and_named(tmp_path, binary, labels):
    image = np.array(labels, np.int64).reshape(1, 1, 3).repeat(2, axis=0)
    mesh = grid_mesh(image, names={labels[0]: "bone"})
    path = write_mesh(mesh, tmp_path / "m.msh", binary=binary)[0]
    expected = {("bone" if m == labels[0] else f"material_{m}"): k + 1
                for k, m in enumerate(sorted(labels))}
    groups, _ = gmsh_reads(path, 3)
    assert {name: tag for name, (tag, _) in groups.items()} == expected
    for m in labels:
        name = "bone" if m == labels[0] else f"material_{m}"
        assert groups[name][1] == np.count_nonzero(mesh.material == m)
    assert {name: int(v[0]) for name, v in meshio.read(path).field_data.items()
            if v[1] == 3} == expected
    back = read_mesh(path)
    np.testing.assert_array_equal(np.sort(back.material), np.sort(mesh.material))
    assert back.material_names[labels[0]] == "bone"


def test_small_labels_keep_their_ids_as_tags():
    assert gmsh_tags(np.array([0, 1, 2**31 - 2])) == {0: 2**31 - 1, 1: 1, 2**31 - 2: 2**31 - 2}
    assert gmsh_tags(np.array([1, 5])) == {1: 1, 5: 5}


def test_labels_doubles_cannot_hold_are_refused_before_meshing(tmp_path, capsys):
    image = np.zeros((3, 3, 3), np.int64)
    image[1:] = 2**60 + 1
    np.save(tmp_path / "l.npy", image)
    code = main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.msh")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "exact up to 2^53" in err and "write .vtu or .xdmf" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy"]
    # excluded, the large label is no obstacle
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.msh"),
                 "--exclude", str(2**60 + 1)]) == 0
    with pytest.raises(ValueError, match="exact up to 2"):
        write_mesh(grid_mesh(image), tmp_path / "n.msh")
    assert not (tmp_path / "n.msh").exists()
