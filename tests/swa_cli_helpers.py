"""The command line run in this process, shared by the tests that drive it (not a test
module)."""

from __future__ import annotations

from napari_swa_imesh.cli import main


def run(capsys, *argv) -> tuple[int, str, str]:
    """``swa-imesh ARGV`` (each argument through ``str``): the exit code, stdout, stderr."""
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err
