"""The mesh formats are one record each in a registry: every dispatcher looks a suffix up
there, an unknown suffix is refused in one sentence (never written as some default
format), and a new format is one record."""

from __future__ import annotations

import re

import numpy as np
import pytest

from napari_swa_imesh.cli import main
from napari_swa_imesh.mesh import (
    MESH_SUFFIXES,
    MeshFormat,
    mesh_format,
    mesh_formats,
    mesh_labels,
    read_mesh,
    write_mesh,
)
from napari_swa_imesh.mesh.formats import _registry
from napari_swa_imesh.mesh.formats._export import check_write_options, mesh_output_paths
from napari_swa_imesh.mesh.formats._registry import UnknownSuffixError, register_format


def _mesh():
    labels = np.ones((4, 5), np.uint8)
    labels[1:3, 2:4] = 2
    return mesh_labels(labels)


def test_every_suffix_names_one_format_and_each_format_is_listed_once():
    formats = mesh_formats()
    assert len({f.name for f in formats}) == len(formats)
    assert [s for f in formats for s in f.suffixes] == list(MESH_SUFFIXES)
    for suffix in MESH_SUFFIXES:
        fmt = mesh_format(f"dir/Mesh{suffix.upper()}")       # case does not matter
        assert suffix in fmt.suffixes and fmt.description == MESH_SUFFIXES[suffix]
    assert mesh_format("m.node") is mesh_format("m.ele")


@pytest.mark.parametrize("name", ["mesh.stl", "mesh", "mesh.vtu.bak", "mesh.h5"])
def test_an_unknown_suffix_is_refused_in_one_sentence_and_nothing_is_written(tmp_path, name):
    mesh = _mesh()
    for call in (lambda: write_mesh(mesh, tmp_path / name),
                 lambda: mesh_output_paths(tmp_path / name),
                 lambda: check_write_options(tmp_path / name)):
        with pytest.raises(UnknownSuffixError, match=r"unknown suffix .*; use one of \.vtu, "):
            call()
    with pytest.raises(ValueError, match="cannot read a mesh from"):
        (tmp_path / name).write_text("x")
        read_mesh(tmp_path / name)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]   # only the planted file


def test_the_command_line_exits_2_on_an_unknown_suffix_before_meshing(tmp_path, capsys):
    np.save(tmp_path / "l.npy", np.ones((4, 4), np.uint8))
    code = main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.stl")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "unknown suffix '.stl'" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy"]


@pytest.mark.parametrize(("flags", "said"), [
    (["-o", "m.vtk", "--facet-groups", "xmin"],
     "legacy .vtk holds no facet groups; write .vtu (its groups go to <stem>_facets.vtu) or "
     ".msh, or drop --facet-groups."),
    (["-o", "m.vtu", "--facet-groups", "xmin,", ],
     "--facet-groups expects all, none or names separated by commas"),
])
def test_the_command_line_names_its_flag_in_the_library_s_refusals(tmp_path, capsys, flags,
                                                                     said):
    np.save(tmp_path / "l.npy", np.ones((4, 4), np.uint8))
    code = main(["mesh", str(tmp_path / "l.npy"), *[str(tmp_path / f) if f.startswith("m.")
                                                    else f for f in flags]])
    err = capsys.readouterr().err
    assert code == 2 and said in err, err


def test_the_library_names_its_keyword():
    with pytest.raises(ValueError, match=re.escape("or leave the facet groups out.")):
        check_write_options("m.vtk", facet_groups=["xmin"])
    with pytest.raises(ValueError, match="^facet_groups must be 'all', 'none'"):
        check_write_options("m.vtu", facet_groups="{bad}")       # braces pass through


def test_a_new_format_is_one_record(tmp_path, monkeypatch):
    """A toy format registered once is written, listed and refused like the others."""
    monkeypatch.setattr(_registry, "_FORMATS", dict(_registry._FORMATS))
    seen = {}

    def write(ex, temps, **options):
        seen.update(options)
        temps[0].write_text(f"{len(ex.points)} points\n")
        temps[1].write_text(f"{len(ex.all_cells())} cells\n")

    toy = MeshFormat("toy", (".toy",), "points and cells counted",
                     files=lambda p: [p, p.with_suffix(".toycells")], write=write,
                     facet_groups=False, options=frozenset({"binary"}))
    register_format(toy)
    mesh = _mesh()
    written = write_mesh(mesh, tmp_path / "m.toy", binary=False)
    assert [p.name for p in written] == ["m.toy", "m.toycells"] and seen == {"binary": False}
    assert (tmp_path / "m.toy").read_text() == f"{len(mesh.points)} points\n"
    assert mesh_format("x.TOY") is toy and toy in mesh_formats()
    with pytest.raises(ValueError, match="already"):
        register_format(MeshFormat("other", (".toy",), "", files=lambda p: [p], write=write))
    (tmp_path / "m.toy").unlink()
    with pytest.raises(FileExistsError, match="m.toycells already exists"):
        write_mesh(mesh, tmp_path / "m.toy")                  # the twin is checked too


def test_the_files_of_a_write_are_the_records_own(tmp_path):
    assert [p.name for p in mesh_output_paths(tmp_path / "m.ele", ndim=3)] == [
        "m.node", "m.ele", "m.face"]
    assert [p.name for p in mesh_output_paths(tmp_path / "m.xdmf", ndim=2)] == [
        "m.xdmf", "m.h5", "m_xdmf_facets.vtu"]
    assert [p.name for p in mesh_output_paths(tmp_path / "m.vtu", facet_groups="none")] == [
        "m.vtu"]
    assert [p.name for p in mesh_output_paths(tmp_path / "m.msh")] == ["m.msh"]
