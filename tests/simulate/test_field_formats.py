"""Field files take their suffixes and twins from the mesh format registry (issue 24)."""

from __future__ import annotations

import pytest

from napari_swa_imesh.mesh import mesh_formats
from napari_swa_imesh.simulate import _output
from napari_swa_imesh.simulate._output import FIELD_SUFFIXES, check_field_path, check_series_path


def test_every_format_the_registry_says_holds_fields_has_a_field_writer():
    holding = {f.name for f in mesh_formats() if f.fields}
    assert set(_output._FIELD_WRITERS) == holding
    assert {f.name for f in mesh_formats() if f.series} <= holding
    assert FIELD_SUFFIXES == (".vtu", ".xdmf")          # as the help texts always said


def test_field_files_are_the_registry_records_files(tmp_path):
    pytest.importorskip("h5py")
    assert check_field_path(tmp_path / "f.VTU") == [tmp_path / "f.VTU"]
    assert check_field_path(tmp_path / "f.xdmf") == [tmp_path / "f.xdmf", tmp_path / "f.h5"]
    assert check_series_path(tmp_path / "s.xdmf") == [tmp_path / "s.xdmf", tmp_path / "s.h5"]


def test_a_suffix_without_fields_is_refused_naming_those_with_them(tmp_path):
    with pytest.raises(ValueError, match=r"cannot write a field to 'f\.msh': use \.vtu or \.xdmf"):
        check_field_path(tmp_path / "f.msh")
    with pytest.raises(ValueError, match=r"name the output 's\.xdmf' instead of 's\.vtu'"):
        check_series_path(tmp_path / "s.vtu")
