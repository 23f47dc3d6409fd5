"""SWA segmentation benchmark: accuracy tables and speed/memory against a random-forest peer.

Run:  python benchmarks/bench_swa.py [--quick] [--skip-speed]

1. Two-texture mosaics (scikit-image's photos, histogram-equalised; trained on the photos'
   top halves, tested on a mosaic of their bottom halves): mean Dice for every scale,
   feature set and classifier.
2. A synthetic 3-D tissue phantom (three materials, Rician noise, smooth bias), samples
   from the truth: Dice per material of GM with F1 at each scale.
3. Speed and peak memory on a 256^3 float32 volume: moments for all scales plus GM
   classification, against scikit-image's multiscale_basic_features + random forest on
   the same volume and training boxes, each in its own process, ratio printed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np


def mosaic_table(quick: bool) -> None:
    from napari_swa_imesh.data import texture_mosaic, texture_training
    from napari_swa_imesh.segmentation import FEATURE_SETS, dice_scores, segment

    pairs = [("brick", "grass")] if quick else [("brick", "grass"), ("brick", "gravel"),
                                                ("grass", "gravel")]
    layouts = ["halves"] if quick else ["halves", "voronoi"]
    classifiers = ["gm"] if quick else ["gm", "md", "lvq"]
    sets = ["F1"] if quick else list(FEATURE_SETS)
    scales = range(1, 7)
    print("\n## Two-texture mosaics: mean Dice (rows: features+classifier, columns: scale)")
    for pair in pairs:
        train, samples = texture_training(pair)
        for layout in layouts:
            mosaic, truth = texture_mosaic(pair, layout=layout)
            print(f"\n{pair[0]}/{pair[1]}, {layout} (suggested RES of the training samples: "
                  f"{segment(train, samples).res.suggested_scale})")
            print("set  clf  " + " ".join(f"  j={j} " for j in scales) + "   best")
            for fs in sets:
                for clf in classifiers:
                    row = []
                    for j in scales:
                        if fs in ("F3", "F4", "F6", "F7") and j < 2:
                            row.append(np.nan)
                            continue
                        try:
                            fitted = segment(train, samples, method="reference", scale=j,
                                             feature_set=fs, classifier=clf)
                            res = segment(mosaic, model=fitted.model)
                            row.append(np.mean(list(dice_scores(res.labels, truth).values())))
                        except ValueError:
                            row.append(np.nan)
                    best = np.nanmax(row)
                    print(f"{fs:4s} {clf:4s} " + " ".join(f"{v:6.3f}" for v in row)
                          + f"  {best:6.3f} (j={int(np.nanargmax(row)) + 1})")


def phantom_table(quick: bool) -> None:
    from napari_swa_imesh.data import TISSUE_NAMES, tissue_phantom
    from napari_swa_imesh.segmentation import dice_scores, samples_from_truth, segment

    print("\n## 3-D tissue phantom (96x128x128, spacing 2x1x1): GM + F1, samples from truth")
    for noise, bias in ([(0.03, 0.2)] if quick else [(0.03, 0.0), (0.03, 0.2), (0.09, 0.4)]):
        image, truth = tissue_phantom((96, 128, 128), noise=noise, bias=bias, seed=1)
        print(f"\nnoise {noise:.0%}, bias {bias:.0%}")
        print("scale  " + "  ".join(f"{TISSUE_NAMES[k]:>12s}" for k in (1, 2, 3)) + "   seconds")
        for j in (0, 1, 2, 3):
            samples = samples_from_truth(truth, scale=j, per_material=6)
            t = time.perf_counter()
            res = segment(image, samples, method="reference", scale=j)
            sec = time.perf_counter() - t
            d = dice_scores(res.labels, truth)
            print(f"{j:5d}  " + "  ".join(f"{d[k]:12.3f}" for k in (1, 2, 3)) + f"   {sec:7.2f}")


SPEED_SWA = r"""
import json, resource, sys, time
import numpy as np
from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import moment_pyramid, samples_from_truth, SWAModel
image, truth = tissue_phantom((256, 256, 256), spacing=(1, 1, 1), noise=0.03, bias=0.2, seed=2)
samples = samples_from_truth(truth, scale=2, per_material=6)
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
pyr = moment_pyramid(image, max_scale=8)
t1 = time.perf_counter()
model = SWAModel(scale=2).fit(image, samples)
t2 = time.perf_counter()
tiles = model.predict_tiles(image)
t3 = time.perf_counter()
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"moments_all_scales": t1 - t0, "fit": t2 - t1, "classify": t3 - t2,
                  "total": t3 - t0, "peak_gb": peak / 2**20, "input_gb": image.nbytes / 2**30}))
"""

SPEED_RF = r"""
import json, resource, sys, time
import numpy as np
from skimage.feature import multiscale_basic_features
from sklearn.ensemble import RandomForestClassifier
from napari_swa_imesh.data import tissue_phantom
from napari_swa_imesh.segmentation import samples_from_truth
image, truth = tissue_phantom((256, 256, 256), spacing=(1, 1, 1), noise=0.03, bias=0.2, seed=2)
samples = samples_from_truth(truth, scale=2, per_material=6)
t0 = time.perf_counter()
feats = multiscale_basic_features(image, intensity=True, edges=True, texture=True,
                                  sigma_min=1, sigma_max=8, workers=2)
t1 = time.perf_counter()
train = np.zeros(image.shape, np.int32)
for b in samples.boxes:
    train[b.slices] = b.label
rng = np.random.default_rng(0)
idx = np.flatnonzero(train.ravel())
idx = rng.choice(idx, min(idx.size, 200_000), replace=False)
X = feats.reshape(-1, feats.shape[-1])
clf = RandomForestClassifier(n_estimators=50, max_depth=12, n_jobs=2, random_state=0)
clf.fit(X[idx], train.ravel()[idx])
t2 = time.perf_counter()
pred = clf.predict(X)
t3 = time.perf_counter()
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"features": t1 - t0, "fit": t2 - t1, "classify": t3 - t2, "total": t3 - t0,
                  "peak_gb": peak / 2**20}))
"""


def speed_table() -> None:
    print("\n## Speed and memory, 256^3 float32 (each in its own process)")
    rows = {}
    for name, code in (("SWA moments (all scales) + GM at scale 2", SPEED_SWA),
                       ("skimage multiscale_basic_features + random forest", SPEED_RF)):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        if out.returncode != 0:
            print(f"{name}: failed: {out.stderr.strip().splitlines()[-1:]}")
            continue
        rows[name] = json.loads(out.stdout.strip().splitlines()[-1])
        r = rows[name]
        print(f"{name}: " + ", ".join(f"{k} {v:.2f}" + ("" if "gb" in k else " s")
                                      for k, v in r.items()))
    if len(rows) == 2:
        a, b = rows.values()
        print(f"ratio random forest / SWA: time {b['total'] / a['total']:.1f}x, "
              f"peak memory {b['peak_gb'] / a['peak_gb']:.1f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one pair, F1 + GM, one phantom")
    ap.add_argument("--skip-speed", action="store_true")
    args = ap.parse_args()
    mosaic_table(args.quick)
    phantom_table(args.quick)
    if not args.skip_speed:
        speed_table()


if __name__ == "__main__":
    main()
