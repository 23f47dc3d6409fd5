"""The benchmarks' children report their own peak memory, not their parent's."""

import resource
import subprocess
import sys

import numpy as np
import pytest
from benchmarks._peak import PEAK_SOURCE


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="VmHWM is Linux's")
def test_a_child_of_a_large_process_reports_its_own_peak():
    held = np.ones(400 * 2 ** 20 // 8)          # 400 MB resident in this process
    code = PEAK_SOURCE + (
        "print(peak_bytes())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    own = int(out[0])
    assert held.sum() > 0 and resource.getrusage(resource.RUSAGE_SELF).ru_maxrss > 4e5
    # a bare interpreter: some 10 MB; ru_maxrss here says the parent's 400 MB or more
    assert 1e6 < own < 200 * 2 ** 20, own
