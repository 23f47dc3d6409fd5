import subprocess
import sys


def test_library_import_leaves_gui_packages_out():
    code = (
        "import sys, napari_swa_imesh, napari_swa_imesh.segmentation, napari_swa_imesh.mesh, "
        "napari_swa_imesh.cli, napari_swa_imesh.data\n"
        "bad = [m for m in ('napari', 'qtpy', 'PyQt6', 'PyQt5', 'PySide6', 'magicgui', "
        "'matplotlib.pyplot', 'vispy') if m in sys.modules]\n"
        "print(','.join(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == ""


def test_mesh_command_imports_neither_segmentation_nor_ndimage(tmp_path):
    """``swa-imesh mesh`` imports only what meshing needs: the segmentation package and
    scipy.ndimage took a second or more of the command's start."""
    import numpy as np

    np.save(tmp_path / "lab.npy", (np.indices((6, 6, 6)).sum(0) // 5).astype(np.uint8))
    code = (
        "import sys\nfrom napari_swa_imesh.cli import main\n"
        f"assert main(['mesh', {str(tmp_path / 'lab.npy')!r}, '-o', "
        f"{str(tmp_path / 'm.vtu')!r}]) == 0\n"
        "print('loaded:', *(m for m in ('napari_swa_imesh.segmentation', 'scipy.ndimage', "
        "'napari_swa_imesh.simulate') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip().splitlines()[-1] == "loaded:"


def test_command_table_names_every_registered_command():
    """cli.COMMAND_MODULES (which group registers which command) matches the parsers."""
    from napari_swa_imesh.cli import COMMAND_MODULES, build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    listed = [c for names in COMMAND_MODULES.values() for c in names]
    assert sorted(sub.choices) == sorted(listed)
    for names in COMMAND_MODULES.values():
        for name in names:
            one = next(a for a in build_parser(name)._actions if a.dest == "command")
            assert set(one.choices) == set(names)
