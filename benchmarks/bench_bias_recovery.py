"""How much of the accuracy a bias field costs the bias correction wins back (issue 25).

    python benchmarks/bench_bias_recovery.py [--generator heldout|dev] [--quick]

For every variant with a field and its no-field partner (same contrast, noise, voxels),
per case of the generator (``anatomy_heldout.py`` by default: nothing was tuned on it;
``dev``: the tuning generator's dev split, the only one to tune on):

* Dice CSF / GM / WM inside the brain of the default (``bias_correction="auto"``) and of
  ``bias_correction=False``, on the image without and with the field;
* the *ceiling*: ``bias_correction=False`` on the image divided by the true field (the
  noise-free image with the field over the one without), what a perfect estimator gives;
* recovery = (Dice corrected - Dice bias off) / (Dice no field - Dice bias off) per
  material for GM and WM (also of the ceiling: the ceiling is not 100 % because the noise
  and the texture differ between the two images, and the location-dependent tissue
  intensities of the held-out generator interact with the field);
* the no-field cost: Dice bias off - Dice default on the image without a field;
* the field error: std of ``log(estimated / true)`` (each centred) over the brain, against
  the std of the true log field (1.0: no better than no correction).

Each case is two fits and predictions per image (about 20 s each on one core).
"""

from __future__ import annotations

import argparse
import time
import warnings

try:                    # imported as benchmarks.bench_bias_recovery
    from . import anatomy, anatomy_heldout
except ImportError:     # run as a script
    import anatomy
    import anatomy_heldout
import numpy as np

__all__ = ["dice3", "true_field", "estimated_field", "recovery", "main"]

_FLOOR = 0.02           # |noise-free intensity| below this: no field defined (air)


def dice3(model_kwargs: dict, image, truth, brain):
    """(CSF, GM, WM) Dice inside the brain of a RecommendedModel fitted on the boxes of
    `truth` and predicting `image`; and the model."""
    from napari_swa_imesh.segmentation import RecommendedModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        model = RecommendedModel(**model_kwargs).fit(image, anatomy.samples_for(truth))
        labels = model.predict(image)
    d = anatomy.brain_dice(labels, truth, brain)
    return np.array([d[k] for k in sorted(anatomy.TISSUES)]), model


def true_field(clean_field, clean) -> np.ndarray:
    """The field as the ratio of the noise-free images with and without it; where the
    noise-free image is (nearly) 0, the nearest defined value."""
    from scipy import ndimage as ndi

    ok = np.abs(clean) > _FLOOR
    ratio = np.where(ok, clean_field / np.where(ok, clean, 1), 1).astype(np.float32)
    idx = ndi.distance_transform_edt(~ok, return_distances=False, return_indices=True)
    return ratio[tuple(idx)]


def estimated_field(model, image) -> np.ndarray:
    """The field the model divides `image` by when predicting (ones when it does not
    correct); the same rounds as :meth:`RecommendedModel._classify`."""
    from napari_swa_imesh.segmentation._recommended import BIAS_ROUNDS

    base = model._standardised(image)
    if not model.bias_correction:
        return np.ones(image.shape, np.float32)
    work, field = base, None
    for _ in range(BIAS_ROUNDS):
        field = model._bias_field(base, work)
        work = base / field
    return field            # the last round's field is the one the image is divided by


def recovery(corrected: float, off: float, clean: float) -> float:
    """(corrected - off) / (clean - off); nan when the field costs nothing."""
    lost = clean - off
    return float((corrected - off) / lost) if abs(lost) > 1e-3 else float("nan")


def _cases(generator: str, quick: bool):
    """Yield (label, case name, no-field image, field image, true field, truth, brain)."""
    if generator == "heldout":
        H = anatomy_heldout
        for contrast, noise, bias, spacing in H.VARIANTS:
            if not bias:
                continue
            for crop, anat, seed in H.CASES[:1] if quick else H.CASES:
                flat, truth, brain = H.make_case(crop, anat, noise, 0.0, spacing, seed,
                                                 contrast)
                image, _, _ = H.make_case(crop, anat, noise, bias, spacing, seed, contrast)
                c0, _, _ = H.make_case(crop, anat, 0.0, 0.0, spacing, seed, contrast)
                c1, _, _ = H.make_case(crop, anat, 0.0, bias, spacing, seed, contrast)
                label = (f"{contrast}, noise {noise:.0%}, bias {bias:.0%}, "
                         f"{'x'.join(f'{s:g}' for s in spacing)} mm")
                yield label, crop, flat, image, true_field(c1, c0), truth, brain
    else:
        for noise, bias in anatomy.VARIANTS:
            if not bias:
                continue
            for crop, anat, seeds in anatomy.SPLITS["dev"]:
                for seed in seeds[:1] if quick else seeds:
                    flat, truth, brain = anatomy.make_case(crop, anat, noise, 0.0, seed)
                    image, _, _ = anatomy.make_case(crop, anat, noise, bias, seed)
                    c0, _, _ = anatomy.make_case(crop, anat, 0.0, 0.0, seed)
                    c1, _, _ = anatomy.make_case(crop, anat, 0.0, bias, seed)
                    yield (f"noise {noise:.0%}, bias {bias:.0%}", f"{crop}/s{seed}", flat,
                           image, true_field(c1, c0), truth, brain)


def main(argv=None) -> None:
    """Print the per-case lines and the per-variant recovery table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--generator", choices=["heldout", "dev"], default="heldout")
    ap.add_argument("--quick", action="store_true", help="one case per variant")
    args = ap.parse_args(argv)
    rows: dict[str, list] = {}
    for label, name, flat, image, field, truth, brain in _cases(args.generator, args.quick):
        t = time.perf_counter()
        clean, _ = dice3({"bias_correction": False}, flat, truth, brain)
        clean_auto, _ = dice3({}, flat, truth, brain)
        off, _ = dice3({"bias_correction": False}, image, truth, brain)
        auto, model = dice3({}, image, truth, brain)
        ceiling, _ = dice3({"bias_correction": False}, image / field, truth, brain)
        lt = np.log(field[brain])
        le = np.log(estimated_field(model, image)[brain])
        err = float(np.std((lt - lt.mean()) - (le - le.mean())) / max(lt.std(), 1e-12))
        rows.setdefault(label, []).append((clean, clean_auto, off, auto, ceiling, err))
        print(f"  {label} {name}: no field off {_f(clean)} default {_f(clean_auto)}; "
              f"field off {_f(off)} default {_f(auto)} true field removed {_f(ceiling)}; "
              f"field error {err:.2f} (range {model.scores['bias_range']}) "
              f"[{time.perf_counter() - t:.0f} s]", flush=True)
    print(f"\n| {args.generator} variant | no field (off) | no-field cost GM / WM | field, "
          "bias off | field, default | field, true field removed | recovery GM / WM | "
          "ceiling recovery GM / WM | field error |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, runs in rows.items():
        clean, clean_auto, off, auto, ceiling, err = (np.mean([r[i] for r in runs], axis=0)
                                                      for i in range(6))
        rec = [recovery(auto[k], off[k], clean[k]) for k in (1, 2)]
        cei = [recovery(ceiling[k], off[k], clean[k]) for k in (1, 2)]
        cost = clean - clean_auto
        print(f"| {label} | {_f(clean)} | {cost[1]:+.3f} / {cost[2]:+.3f} | {_f(off)} | "
              f"{_f(auto)} | {_f(ceiling)} | {_p(rec)} | {_p(cei)} | {err:.2f} |")


def _f(d) -> str:
    return " / ".join(f"{v:.3f}"[1:] if v < 1 else "1.00" for v in d)


def _p(r) -> str:
    return " / ".join("n/a" if np.isnan(v) else f"{v:.0%}" for v in r)


if __name__ == "__main__":
    main()
