"""The command line from Python: segment, mesh and simulate files as a shell would.

``main`` is what the ``swa-imesh`` command runs; it returns the exit status (0, or 2 with
one sentence on stderr when an input or output is refused).
"""

import json

import numpy as np

from napari_swa_imesh.cli import main

labels = np.zeros((16, 16), np.uint8)
labels[4:12, 4:12] = 1
labels[:, :4] = 2
np.save("labels.npy", labels)

assert main(["mesh", "labels.npy", "-o", "labels.vtu", "--force"]) == 0
assert main(["simulate", "labels.npy", "-k", "0=1", "1=10", "2=0.1", "--order", "1",
             "--adapt", "0", "--report", "report.json"]) == 0
report = json.load(open("report.json"))
print(sorted(report))
# an output that exists is never replaced without --force: exit status 2, nothing written
assert main(["mesh", "labels.npy", "-o", "labels.vtu"]) == 2
