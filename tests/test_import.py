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
