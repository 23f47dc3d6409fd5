"""``leaf_tables.npz`` is loaded on first use, not when the mesher is imported."""

import subprocess
import sys

PROBE = """
import napari_swa_imesh.mesh
from napari_swa_imesh.mesh.mesher import _templates_luts as luts
before = luts._leaf_tables_loaded
n_plain = len(dict.__getitem__(luts.TEMPLATES, 3))
table = luts.LEAF_TABLE.get(3)
print(before, luts._leaf_tables_loaded, table is not None,
      len(luts.TEMPLATES[3]) == n_plain + len(table.simplex),
      luts.TABLE_FIRST_ID[3] == n_plain)
"""


def test_the_leaf_table_is_read_on_first_use_and_extends_the_templates():
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "True", "True", "True", "True"]
