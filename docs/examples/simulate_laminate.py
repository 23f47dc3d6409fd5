"""Simulate: the effective conductivity of a two-layer laminate, against its exact value.

Across the layers the layers conduct in series (the harmonic mean), along them in parallel
(the arithmetic mean); these are also the Reuss and Voigt bounds every k_eff lies in.
"""

import math

import numpy as np

from napari_swa_imesh.simulate import simulate

labels = np.ones((8, 16), np.int64)
labels[:, 8:] = 2                                       # two halves along x (columns)
k = {1: 1.0, 2: 10.0}
result = simulate(labels, k, order=1, adapt=0)

harmonic = 2 / (1 / k[1] + 1 / k[2])
arithmetic = (k[1] + k[2]) / 2
print(result.describe())
assert math.isclose(result.k_eff["x"], harmonic, rel_tol=1e-8)      # in series
assert math.isclose(result.k_eff["y"], arithmetic, rel_tol=1e-8)    # in parallel
reuss, voigt = result.bounds["x"]
assert reuss - 1e-9 <= result.k_eff["x"] <= voigt + 1e-9
