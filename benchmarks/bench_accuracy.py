"""Segmentation accuracy: the recommended method against the reference and common peers.

Run:  python benchmarks/bench_accuracy.py [--quick] [--skip-cost] [--ants-python PY]
      [--anatomy dev|val|both|none] [--only-anatomy] [--markdown docs/benchmarks/accuracy.md]
      [--variants TEXT...]

Every method sees the same data and the same sample boxes:

* **reference** - F1 moments + GM on tiles at the suggested RES (``method="reference"``);
* **recommended** - the package default (``segment(image, samples)``);
* **k-means** - on intensity, unsupervised, clusters mapped to materials by mean intensity
  (cluster order against the materials' mean intensity in the sample boxes);
* **RF** - scikit-image ``multiscale_basic_features`` + a random forest (50 trees, depth 12)
  on pixels of the boxes (scikit-image's pixel classifier recipe);
* **Atropos** (3-D only) - ANTs Atropos through ANTsPy (k-means init, MRF 0.2, 1x1x1), run
  by a separate Python that has ``antspyx`` (``--ants-python``; antspyx pins numpy < 2.4, so
  it lives in its own venv); without it, **Atropos-style (ours)**: k-means init, Gaussian
  mixture EM and a Potts ICM on intensity, unsupervised, classes mapped by mean.

Data:

* texture mosaics (256x256) of histogram-equalised photos bundled with scikit-image (brick,
  grass, gravel, moon, hubble), trained on the photos' top halves, tested on mosaics of
  their bottom halves: 2, 3, 4 and 5 textures, straight ("halves") and Voronoi boundaries;
* 3-D tissue phantoms (96x128x128, spacing 2x1x1; CSF, grey and white matter), Rician noise
  3 % and 9 %, smooth multiplicative bias 0 % and 40 %; sample boxes = the 6 largest
  homogeneous blocks per material of the truth (``samples_from_truth``, scale 2).

* real-anatomy MR phantoms (``anatomy.py``: MNI152 2009 GM/WM maps bundled with nilearn,
  warped, quadrant crops, partial-volume intensities, Rician noise 3/9 %, bias 0/40 %):
  ``--anatomy val`` (default) is the held-out split nothing was tuned on, ``dev`` the
  development split; boxes from the truth as ``samples-from-truth --scale 2``; Dice inside
  the brain; k-means and Atropos get the brain mask (as on MR), the default only the boxes.
  This is the *tuning* generator; ``anatomy_heldout.py`` is an independent one (hard labels
  + PSF, tissue intensity by location, T1 and T2 contrasts, Gaussian noise, polynomial
  field, 1 mm and 1.5x0.94x0.94 mm) that nothing was tuned on, reported after it in the
  same columns (also: the default without bias correction, and k-means + GMM + MRF on the
  brain mask), then both side by side with the issue-25 goal judged per variant
  (``accuracy_report.py``); ``--markdown PATH`` writes that table (and the mosaics' mean
  Dice, when they ran) to a page, e.g. ``docs/benchmarks/accuracy.md``.

Reported: Dice per material and mean, wall time (fit + predict, seconds) and peak memory
(tracemalloc: numpy/Python allocations of the run; for Atropos the growth of the child
process's peak RSS, VmHWM). Last, the cost of the recommended method and of the RF on a
256^3 volume, each in a fresh process (peak RSS; the input alone is 64 MB).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc

import numpy as np

import accuracy_report as R

MOSAICS_FULL = [
    (("brick", "grass"), "halves"), (("grass", "gravel"), "halves"),
    (("brick", "gravel"), "voronoi"), (("grass", "gravel"), "voronoi"),
    (("brick", "grass", "gravel"), "halves"), (("brick", "grass", "gravel"), "voronoi"),
    (("brick", "grass", "gravel", "moon"), "voronoi"),
    (("brick", "grass", "gravel", "moon", "hubble"), "voronoi"),
]
MOSAICS_QUICK = [(("brick", "grass"), "halves"), (("brick", "grass", "gravel"), "voronoi")]
PHANTOMS_FULL = [(0.03, 0.0), (0.03, 0.4), (0.09, 0.0), (0.09, 0.4)]
PHANTOMS_QUICK = [(0.09, 0.4)]
PHANTOM_SHAPE = (96, 128, 128)


# -- peers -----------------------------------------------------------------------------------
def box_mask(shape, samples) -> np.ndarray:
    mask = np.zeros(shape, np.int32)
    for b in samples.boxes:
        mask[b.slices] = b.label
    return mask


def map_by_mean(clusters: np.ndarray, centres: np.ndarray, train, samples) -> np.ndarray:
    """Cluster k -> material, matching the order of cluster centres to the order of the
    materials' mean intensity in their boxes."""
    means = [np.mean(np.concatenate([train[b.slices].ravel() for b in samples.boxes_of(m)]))
             for m in samples.labels]
    mats = np.asarray(samples.labels)[np.argsort(means)]
    lut = np.empty(len(centres), np.int32)
    lut[np.argsort(centres)] = mats
    return lut[clusters]


def run_kmeans(train, samples, test, mask=None):
    from sklearn.cluster import KMeans

    k = len(samples.labels)
    x = test.reshape(-1, 1).astype(np.float32)
    fit = x if mask is None else x[mask.ravel()]
    step = max(1, fit.shape[0] // 200_000)       # fit on a subsample, label every pixel
    km = KMeans(k, n_init=3, random_state=0).fit(fit[::step])
    return map_by_mean(km.predict(x), km.cluster_centers_.ravel(), train, samples
                       ).reshape(test.shape)


def run_rf(train, samples, test):
    from skimage.feature import multiscale_basic_features
    from sklearn.ensemble import RandomForestClassifier

    smax = 16 if test.ndim == 2 else 8
    ftr = multiscale_basic_features(train, sigma_min=1, sigma_max=smax)
    mask = box_mask(train.shape, samples).ravel()
    idx = np.flatnonzero(mask)
    idx = np.random.default_rng(0).choice(idx, min(idx.size, 100_000), replace=False)
    clf = RandomForestClassifier(n_estimators=50, max_depth=12, n_jobs=1, random_state=0)
    clf.fit(ftr.reshape(-1, ftr.shape[-1])[idx], mask[idx])
    del ftr
    fte = ftr_test = multiscale_basic_features(test, sigma_min=1, sigma_max=smax)
    out = clf.predict(fte.reshape(-1, fte.shape[-1])).reshape(test.shape)
    del ftr_test
    return out.astype(np.int32)


def run_atropos_style(train, samples, test, mask=None, iterations: int = 10,
                      beta: float = 1.0):
    """Atropos-style (our implementation): k-means init, Gaussian mixture EM on intensity,
    then Potts ICM on the 2d face neighbours; unsupervised, classes mapped by mean. With
    `mask` (the brain on MR), the clustering and the neighbour votes see only its voxels."""
    from scipy import ndimage as ndi
    from sklearn.cluster import KMeans

    k = len(samples.labels)
    x = test.astype(np.float64)
    flat = x.ravel() if mask is None else x[mask]
    km = KMeans(k, n_init=3, random_state=0).fit(
        flat.reshape(-1, 1)[::max(1, flat.size // 200_000)])
    mu = np.sort(km.cluster_centers_.ravel())
    sd = np.full(k, flat.std() / k)
    w = np.full(k, 1.0 / k)
    inside = np.ones(x.shape, np.float32) if mask is None else mask.astype(np.float32)
    for _ in range(iterations):                  # EM on a subsample (intensity only)
        sub = flat[::max(1, flat.size // 500_000)]
        logp = (-0.5 * ((sub[:, None] - mu) / sd) ** 2 - np.log(sd) + np.log(w))
        r = np.exp(logp - logp.max(1, keepdims=True))
        r /= r.sum(1, keepdims=True)
        n = r.sum(0)
        w, mu = n / n.sum(), (r * sub[:, None]).sum(0) / n
        sd = np.sqrt((r * (sub[:, None] - mu) ** 2).sum(0) / n) + 1e-9
    ll = np.stack([-0.5 * ((x - mu[c]) / sd[c]) ** 2 - np.log(sd[c]) + np.log(w[c])
                   for c in range(k)])
    lab = ll.argmax(0)
    for _ in range(5):                           # ICM: count agreeing face neighbours
        votes = np.stack([ndi.correlate((lab == c) * inside,
                                        _cross(x.ndim), mode="nearest") for c in range(k)])
        lab = (ll + beta * votes).argmax(0)
    return map_by_mean(lab, mu, train, samples).astype(np.int32)


def _cross(d):
    from scipy import ndimage as ndi

    s = ndi.generate_binary_structure(d, 1).astype(np.float32)
    s[(1,) * d] = 0
    return s


# peak-memory helpers pasted into each child script (the ANTs child runs in its own venv,
# so they cannot be imported from here)
PEAK_HELPERS = r"""
def reset_peak():
    # a child starts with its parent's high-water mark (fork copies the parent's memory
    # before exec); Linux resets it on writing 5 to clear_refs
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        pass
def peak_gb():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 2**20
    return float("nan")
"""

ANTS_SCRIPT = r"""
import json, sys, time
import numpy as np, ants
""" + PEAK_HELPERS + r"""img = np.load(sys.argv[1]); k = int(sys.argv[3])
reset_peak()
base = peak_gb()
t = time.perf_counter()
a = ants.from_numpy(img.astype(np.float32))
m = np.load(sys.argv[4]) if len(sys.argv) > 4 else np.ones(img.shape)
mask = ants.from_numpy(m.astype(np.float32))
seg = ants.atropos(a=a, x=mask, i=f"kmeans[{k}]", m="[0.2," + "x".join(["1"] * img.ndim) + "]",
                   c="[5,0]")
lab = seg["segmentation"].numpy().astype(np.int32)
sec = time.perf_counter() - t
means = [float(img[lab == c].mean()) if (lab == c).any() else float("inf")
         for c in range(1, k + 1)]
np.save(sys.argv[2], lab)
print(json.dumps({"seconds": sec, "means": means, "peak_mb": (peak_gb() - base) * 1024}))
"""


def run_ants(python: str, train, samples, test, mask=None):
    """Atropos on `test` (inside `mask` if given, as it is used on MR: brain-masked)."""
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = os.path.join(tmp, "img.npy"), os.path.join(tmp, "lab.npy")
        np.save(src, test.astype(np.float32))
        extra = []
        if mask is not None:
            extra = [os.path.join(tmp, "mask.npy")]
            np.save(extra[0], mask.astype(np.uint8))
        out = subprocess.run([python, "-c", ANTS_SCRIPT, src, dst, str(len(samples.labels)),
                              *extra], capture_output=True, text=True)
        if out.returncode != 0:
            raise RuntimeError(out.stderr.strip().splitlines()[-1:])
        info = json.loads(out.stdout.strip().splitlines()[-1])
        lab = np.load(dst)
    mapped = map_by_mean(np.clip(lab - 1, 0, None), np.asarray(info["means"]), train, samples)
    return mapped, info


# -- running and printing --------------------------------------------------------------------
def measure(fn, *args):
    tracemalloc.start()
    t = time.perf_counter()
    out = fn(*args)
    sec = time.perf_counter() - t
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return out, sec, peak / 2**20


def run_reference(train, samples, test):
    from napari_swa_imesh.segmentation import segment

    fitted = segment(train, samples, method="reference")
    return segment(test, model=fitted.model).labels


def run_recommended(train, samples, test):
    from napari_swa_imesh.segmentation import segment

    fitted = segment(train, samples)
    run_recommended.last = fitted
    return segment(test, model=fitted.model).labels


def table(title, names, truth, runs, rows_out):
    from napari_swa_imesh.segmentation import dice_scores

    mats = [int(m) for m in np.unique(truth) if m > 0]
    print(f"\n### {title}")
    head = f"{'method':28s}" + "".join(f"{n[:11]:>12s}" for n in names) + \
        f"{'mean':>8s}{'s':>8s}{'MB':>8s}"
    print(head)
    best_peer = -1.0
    result = {}
    for method, (labels, sec, mb) in runs.items():
        d = dice_scores(labels, truth, materials=mats)
        mean = float(np.mean(list(d.values())))
        result[method] = {"dice": d, "mean": mean, "seconds": sec, "mb": mb}
        print(f"{method:28s}" + "".join(f"{d[m]:12.3f}" for m in mats)
              + f"{mean:8.3f}{sec:8.1f}{mb:8.0f}")
        if method != "recommended":
            best_peer = max(best_peer, mean)
    rec = result["recommended"]["mean"]
    verdict = "meets" if rec >= best_peer else "MISSES"
    print(f"recommended mean Dice {rec:.3f} vs best peer {best_peer:.3f}: {verdict} the bar")
    rows_out.append((title, result))
    return result


def mosaic_tables(quick, rows):
    from napari_swa_imesh.data import texture_mosaic, texture_training

    print("\n## Texture mosaics (256x256; trained on top halves, tested on bottom halves)")
    for textures, layout in (MOSAICS_QUICK if quick else MOSAICS_FULL):
        train, samples = texture_training(textures)
        test, truth = texture_mosaic(textures, layout=layout)
        runs = {}
        for name, fn in (("reference (F1+GM, RES)", run_reference),
                         ("recommended", run_recommended),
                         ("k-means (intensity)", run_kmeans), ("RF (skimage features)", run_rf)):
            runs[name] = measure(fn, train, samples, test)
        m = run_recommended.last
        title = (f"{'/'.join(textures)}, {layout}: recommended scales "
                 f"{list(m.scales)}, reference RES {m.res.suggested_scale}")
        table(title, list(textures), truth, runs, rows)


def phantom_tables(quick, rows, ants_python):
    from napari_swa_imesh.data import TISSUE_NAMES, tissue_phantom
    from napari_swa_imesh.segmentation import samples_from_truth

    print(f"\n## 3-D tissue phantoms {'x'.join(map(str, PHANTOM_SHAPE))} (samples from truth)")
    for noise, bias in (PHANTOMS_QUICK if quick else PHANTOMS_FULL):
        image, truth = tissue_phantom(PHANTOM_SHAPE, noise=noise, bias=bias, seed=1)
        samples = samples_from_truth(truth, scale=2, per_material=6,
                                     names=dict(TISSUE_NAMES))
        runs = {}
        for name, fn in (("reference (F1+GM, RES)", run_reference),
                         ("recommended", run_recommended),
                         ("k-means (intensity)", run_kmeans), ("RF (skimage features)", run_rf)):
            runs[name] = measure(fn, image, samples, image)
        if ants_python:
            try:
                lab, info = run_ants(ants_python, image, samples, image)
                runs["Atropos (ANTsPy)"] = (lab, info["seconds"], info["peak_mb"])
            except RuntimeError as exc:
                print(f"ANTs failed ({exc}); using the Atropos-style peer")
                ants_python = None
        if not ants_python:
            runs["Atropos-style (ours)"] = measure(run_atropos_style, image, samples, image)
        m = run_recommended.last
        title = (f"noise {noise:.0%}, bias {bias:.0%}: recommended scales {list(m.scales)}, "
                 f"bias correction {m.model.bias_correction}, reference RES "
                 f"{m.res.suggested_scale}")
        res = table(title, [TISSUE_NAMES[k] for k in (1, 2, 3)], truth, runs, rows)
        rec = res["recommended"]["dice"]
        for peer in [p for p in res if p.startswith(("k-means", "Atropos"))]:
            worse = [TISSUE_NAMES[k] for k in (1, 2, 3) if rec[k] < res[peer]["dice"][k]]
            print(f"  per material vs {peer}: "
                  + ("at least as good on every material" if not worse else
                     f"BELOW on {', '.join(worse)}"))


COST = r"""
import json, sys, time
import numpy as np
""" + PEAK_HELPERS + r"""image = np.load(sys.argv[1]); truth = np.load(sys.argv[2])
which = sys.argv[4]
from napari_swa_imesh.segmentation import load_samples, segment, dice_scores
from skimage.feature import multiscale_basic_features
from sklearn.ensemble import RandomForestClassifier
samples = load_samples(sys.argv[3])
reset_peak()
base = peak_gb()
t0 = time.perf_counter()
if which == "recommended":
    labels = segment(image, samples).labels
elif which == "reference":
    labels = segment(image, samples, method="reference").labels
else:
    feats = multiscale_basic_features(image, sigma_min=1, sigma_max=8)
    mask = np.zeros(image.shape, np.int32)
    for b in samples.boxes:
        mask[b.slices] = b.label
    idx = np.flatnonzero(mask)
    idx = np.random.default_rng(0).choice(idx, min(idx.size, 100_000), replace=False)
    X = feats.reshape(-1, feats.shape[-1])
    clf = RandomForestClassifier(n_estimators=50, max_depth=12, n_jobs=1, random_state=0)
    clf.fit(X[idx], mask.ravel()[idx])
    labels = clf.predict(X).reshape(image.shape)
sec = time.perf_counter() - t0
peak = peak_gb()
d = dice_scores(labels, truth)
print(json.dumps({"seconds": sec, "peak_gb": peak, "base_gb": base,
                  "mean_dice": float(np.mean(list(d.values())))}))
"""


def cost_table(with_rf: bool):
    from napari_swa_imesh.data import tissue_phantom
    from napari_swa_imesh.segmentation import samples_from_truth, save_samples

    print("\n## Cost on 256^3 (phantom, noise 3 %, bias 20 %, spacing 1; fit + predict; "
          "each in a fresh process; peak RSS of the process (VmHWM), which already holds "
          "the libraries, image and truth before the run)")
    image, truth = tissue_phantom((256, 256, 256), spacing=(1, 1, 1), noise=0.03, bias=0.2,
                                  seed=2)
    with tempfile.TemporaryDirectory() as tmp:
        paths = [os.path.join(tmp, "image.npy"), os.path.join(tmp, "truth.npy"),
                 os.path.join(tmp, "samples.json")]
        np.save(paths[0], image)
        np.save(paths[1], truth)
        # the boxes are made here: building the truth's tree is not part of any method
        save_samples(samples_from_truth(truth, scale=2, per_material=6), paths[2])
        del image, truth
        for which in ("recommended", "reference") + (("rf",) if with_rf else ()):
            out = subprocess.run([sys.executable, "-c", COST, *paths, which],
                                 capture_output=True, text=True)
            if out.returncode != 0:
                print(f"{which}: failed: {out.stderr.strip().splitlines()[-1:]}")
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"{which:12s} {r['seconds']:8.1f} s   peak {r['peak_gb']:5.2f} GB "
                  f"(after loading {r['base_gb']:4.2f} GB)   mean Dice {r['mean_dice']:.3f}")


def run_recommended_no_bias(train, samples, test):
    import warnings

    from napari_swa_imesh.segmentation import RecommendedModel, segment

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)        # the scale notes, as segment
        model = RecommendedModel(bias_correction=False).fit(train, samples)
    return segment(test, model=model).labels


def anatomy_tables(split, ants_python, variants=None):
    """Per-variant Dice inside the brain, averaged over the split's cases (see anatomy.py)."""
    import anatomy

    variants = variants or anatomy.VARIANTS
    title = (f"Real-anatomy MR phantoms, tuning generator ({split} split; MNI152 2009 maps, "
             f"warped; probability mixing, Rician noise; crops "
             f"{'x'.join(map(str, anatomy.CROP))}; mean of "
             f"{sum(len(s) for _, _, s in anatomy.SPLITS[split])} cases per variant)")
    cases = (((noise, bias), (name, image, truth, brain))
             for name, (noise, bias), image, truth, brain in anatomy.cases(split, variants))
    return generator_table(title, cases, variants, ants_python,
                           lambda v: f"noise {v[0]:.0%}, bias {v[1]:.0%}")


def heldout_tables(ants_python, variants=None):
    """The same table on the independent generator (anatomy_heldout.py): nothing was tuned
    on it."""
    import anatomy_heldout as H

    variants = variants or H.VARIANTS

    title = ("Real-anatomy MR phantoms, held-out generator (anatomy_heldout.py: hard labels "
             "+ PSF, T1 and T2 contrasts, intensity by location, texture, Gaussian noise, "
             "polynomial field; crops "
             f"{'x'.join(f'{e:g}' for e in H.CROP_MM)} mm; mean of {len(H.CASES)} cases "
             "per variant)")
    cases = ((var, (name, image, truth, brain))
             for name, var, image, truth, brain in H.cases(variants))
    return generator_table(title, cases, variants, ants_python,
                           _heldout_label)


def generator_table(title, cases, variants, ants_python, label):
    """Dice (CSF / GM / WM) inside the brain per variant: the default, the default without
    bias correction, and the unsupervised peers on the brain mask."""
    import anatomy

    print(f"\n## {title}")
    # the unsupervised peers get the brain mask, as they are used on MR (without it their
    # darkest cluster is the background); the recommended method gets only the boxes
    peers = [("recommended", run_recommended), ("bias off", run_recommended_no_bias),
             ("k-means (brain mask)", run_kmeans)]
    if ants_python:
        peers.append(("Atropos (brain mask)", lambda tr, s, te, m: run_ants(
            ants_python, tr, s, te, m)[0]))
    else:
        peers.append(("k-means + GMM + MRF (brain mask)", run_atropos_style))
    names = [n for n, _ in peers]
    out = {}
    for var, (name, image, truth, brain) in cases:
        samples = anatomy.samples_for(truth)
        for method, fn in peers:
            masked = method not in ("recommended", "bias off")
            args = (image, samples, image) + ((brain,) if masked else ())
            lab, sec, _ = measure(fn, *args)
            rec = out.setdefault((var, method), [])
            rec.append((anatomy.brain_dice(lab, truth, brain), sec))
            if method == "recommended":
                m = run_recommended.last.model
                print(f"  {name} {label(var)}: scales {m.scales}, bias "
                      f"{m.bias_correction} {m.scores['bias_range']}, Dice "
                      + " ".join(f"{v:.3f}" for v in rec[-1][0].values()), flush=True)
    print("\n| variant | " + " | ".join(f"{n} CSF / GM / WM" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    for var in variants:
        cells = []
        for n in names:
            runs = out[(var, n)]
            d = [np.mean([r[0][k] for r in runs]) for k in anatomy.TISSUES]
            cells.append(" / ".join(f"{v:.3f}"[1:] if v < 1 else "1.00" for v in d)
                         + f" ({np.mean([r[1] for r in runs]):.1f} s)")
        print(f"| {label(var)} | " + " | ".join(cells) + " |")
    return out


def _methods(out) -> list[str]:
    return list(dict.fromkeys(m for _, m in out))


def _anatomy_variants():
    import anatomy

    return anatomy.VARIANTS


def _heldout_label(v) -> str:
    return f"{v[0]}, noise {v[1]:.0%}, bias {v[2]:.0%}, {'x'.join(f'{s:g}' for s in v[3])} mm"


def _chosen(variants, label, patterns):
    """The variants whose label contains one of `patterns` (all of them without any)."""
    return [v for v in variants if not patterns or any(p in label(v) for p in patterns)]


def _tuning_label(v) -> str:
    return f"T1, noise {v[0]:.0%}, bias {v[1]:.0%}, 1 mm"


def _write_markdown(path: str, text: str) -> None:
    from napari_swa_imesh.io import atomic_write

    with atomic_write([path], force=True) as (tmp,):
        tmp.write_text(text)
    print(f"\nwrote {path}")


def summary(rows):
    print("\n## Summary: mean Dice per dataset")
    methods = []
    for _, res in rows:
        methods += [m for m in res if m not in methods]
    print(f"{'dataset':60s}" + "".join(f"{m.split(' ')[0][:11]:>12s}" for m in methods))
    for title, res in rows:
        print(f"{title.split(':')[0][:60]:60s}" + "".join(
            f"{res[m]['mean']:12.3f}" if m in res else f"{'':12s}" for m in methods))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two mosaics and one phantom")
    ap.add_argument("--skip-cost", action="store_true", help="skip the 256^3 cost lines")
    ap.add_argument("--skip-rf-cost", action="store_true",
                    help="skip the RF's 256^3 cost line (about 5 min and 6 GB)")
    ap.add_argument("--anatomy", choices=["dev", "val", "both", "heldout", "none"],
                    default="val",
                    help="real-anatomy MR split(s) of the tuning generator to run, each "
                         "followed by the held-out generator (default: 'val'; 'heldout': "
                         "the held-out generator alone)")
    ap.add_argument("--only-anatomy", action="store_true",
                    help="run only the real-anatomy tables")
    ap.add_argument("--ants-python", default=os.environ.get("ANTS_PYTHON"),
                    help="a Python with antspyx installed (default: $ANTS_PYTHON)")
    ap.add_argument("--markdown", metavar="PATH",
                    help="also write the tuning/held-out table (and the mosaics' mean "
                         "Dice, when run) to this markdown file, e.g. "
                         "docs/benchmarks/accuracy.md")
    ap.add_argument("--variants", nargs="+", metavar="TEXT",
                    help="run only the real-anatomy variants whose row label contains one "
                         "of these texts, e.g. --variants T2 or --variants 'noise 9%%'")
    args = ap.parse_args()
    if args.markdown:
        from napari_swa_imesh.io import check_writable

        try:
            check_writable(args.markdown, force=True)   # the page is regenerated
        except OSError as exc:
            print(f"error: --markdown: {exc}", file=sys.stderr)
            sys.exit(2)
    rows: list = []
    if not args.only_anatomy:
        mosaic_tables(args.quick, rows)
        phantom_tables(args.quick, rows, args.ants_python)
        summary(rows)
    lines: list[str] = []
    names: list[str] = []
    tuning = _chosen(_anatomy_variants(), _tuning_label, args.variants)
    for split in {"both": ["dev", "val"], "none": [], "heldout": []}.get(args.anatomy,
                                                                       [args.anatomy]):
        if not tuning:
            break
        out = anatomy_tables(split, args.ants_python, tuning)
        names = _methods(out)
        lines += R.generator_rows(f"tuning ({split})", out, tuning, _tuning_label, names)
    if args.anatomy != "none":
        import anatomy_heldout as H

        held = _chosen(H.VARIANTS, _heldout_label, args.variants)
        if held:
            out = heldout_tables(args.ants_python, held)
            names = _methods(out)
            lines += R.generator_rows("held-out", out, held, _heldout_label, names)
        print("\n## Tuning and held-out side by side (CSF / GM / WM)\n")
        print("\n".join(R.markdown_page(lines, names, [], "").splitlines()[4:]))
    if args.markdown:
        _write_markdown(args.markdown, R.markdown_page(
            lines, names, R.mosaic_rows(rows),
            "python benchmarks/bench_accuracy.py " + " ".join(sys.argv[1:])))
    if not args.skip_cost and not args.only_anatomy:
        cost_table(with_rf=not (args.quick or args.skip_rf_cost))


if __name__ == "__main__":
    main()
