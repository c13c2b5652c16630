"""Acceptance run: a synthetic burst with known truth written as DNGs, through ``estimate_ground_truth``.

The burst has clipping at both ends (black level 0, so DN 0 and the white level clip, Abdelhamed 2020, eq.
5.3), hot pixels (also in a dark sequence, written as DNGs too), flicker (0.2 % per frame plus
two frames 15 % darker), and a smooth OIS-like drift field. Compared with the exact noise-free
reference frame (scaled by the kept frames' mean gain):

* the pipeline (defects from the dark DNGs, intensity alignment, local TPS alignment, WLS mean);
* the same with global-translation alignment; with the censored MLE; with the plain mean;
* the plain mean of the frames as they come (no correction at all);
* the oracle: the same pipeline with the plain mean on the *unclipped* frames (same noise draws,
  same quantisation) — the "unclipped-mean oracle" of the acceptance criterion.

Errors are MSE over all pixels except the hot ones, and over the pixels with clipped samples.

Run: python experiments/gt_synthetic_dng.py [--size 768] [--frames 40]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's simcam
from simcam.groundtruth import Burst, GroundTruthConfig, SyntheticBurst, estimate_ground_truth  # noqa: E402
from simcam.groundtruth.synthetic_burst import write_dng_burst  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=768)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--beta1", type=float, default=1e-4)
    args = ap.parse_args()
    white = 4095.0
    kw = dict(shape=(args.size, args.size), n=args.frames, beta1=args.beta1, beta2=args.beta1 / 100, drift_px=4.0,
              flicker_sd=0.002, outliers={3: 0.85, args.frames - 5: 0.85}, hot_fraction=0.002, cell=2.5,
              level=(0.0, 1.03), seed=21)
    sb = SyntheticBurst(**kw)
    oracle_sb = SyntheticBurst(**{**kw, "clip": False})
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        write_dng_burst(sb, Path(tmp) / "burst", white=white)
        write_dng_burst(sb, Path(tmp) / "dark", white=white, dark=30, frames=[])
        print(f"wrote {args.frames} + 30 DNGs ({args.size}x{args.size}) in {time.perf_counter() - t:.1f} s")
        burst = Burst.from_directory(Path(tmp) / "burst")
        dark = Burst.from_directory(Path(tmp) / "dark")
        runs = {}
        for name, cfg in (("pipeline (wls, local)", GroundTruthConfig()),
                          ("pipeline, wls on every pixel", GroundTruthConfig(uncensored_mean=False)),
                          ("global alignment", GroundTruthConfig(alignment="global")),
                          ("pipeline, wls with known NLF", GroundTruthConfig(nlf=(args.beta1, args.beta1 / 100))),
                          ("censored MLE", GroundTruthConfig(method="mle")),
                          ("pipeline, plain mean", GroundTruthConfig(method="mean"))):
            t = time.perf_counter()
            runs[name] = estimate_ground_truth(burst, dark=dark, config=cfg)
            print(f"  {name}: {time.perf_counter() - t:.1f} s")
        frames = [burst.load(i) for i in range(len(burst))]
    g = runs["pipeline (wls, local)"]
    rep = g.report
    # oracle: identical quantisation, no clipping, the pipeline's defect map
    q = lambda x: (np.round(x * white) / white).astype(np.float32)  # noqa: E731
    from simcam.groundtruth import DefectMap

    oracle = estimate_ground_truth(
        Burst.from_arrays([q(oracle_sb.frame(i)) for i in range(sb.n)], clip_low=-np.inf, clip_high=np.inf),
        defects=DefectMap(g.defects, "pipeline"), config=GroundTruthConfig(method="mean"))
    runs["oracle: unclipped, plain mean"] = oracle
    kept = [i for i in range(sb.n) if i not in [d["index"] for d in rep["dropped"]]]
    truth = sb.truth(g.reference) * sb.gains[kept].mean()
    good = ~sb.hot
    clipped = good & (g.n_used < rep["frames_used"]) & g.valid  # censored, yet identifiable
    print(f"dropped frames {[d['index'] for d in rep['dropped']]} (injected {sorted(kw['outliers'])}); reference "
          f"{g.reference}; defects {rep['defects']['count']} (hot pixels {int(sb.hot.sum())}, "
          f"found {int((g.defects & sb.hot).sum())}); max shift {rep['alignment']['max_shift_px']:.2f} px; "
          f"pixels with clipped samples {int(clipped.sum())} ({clipped.mean() * 100:.1f} %); "
          f"fallback {rep['robust_mean']['fallback_pixels']}")
    naive = np.mean(frames, axis=0)
    rows = [(k, v.gt) for k, v in runs.items()] + [("plain mean of raw frames", naive)]
    base = {}
    print(f"{'estimate':34s} {'MSE (x1e-6)':>12s} {'PSNR dB':>8s} {'MSE clipped px':>15s}")
    for k, est in rows:
        e2 = (est.astype(np.float64) - truth) ** 2
        base[k] = (e2[good].mean(), e2[clipped].mean())
        print(f"{k:34s} {base[k][0] * 1e6:12.4f} {10 * np.log10(1 / base[k][0]):8.2f} {base[k][1] * 1e6:15.4f}")
    p = base["pipeline (wls, local)"]
    print(f"margins: pipeline MSE / plain mean of raw frames = {p[0] / base['plain mean of raw frames'][0]:.3f}, "
          f"/ pipeline with plain mean = {p[0] / base['pipeline, plain mean'][0]:.3f}, "
          f"/ global alignment = {p[0] / base['global alignment'][0]:.3f}; "
          f"/ wls on every pixel = {p[0] / base['pipeline, wls on every pixel'][0]:.3f}; "
          f"clipped pixels: WLS / oracle = {p[1] / base['oracle: unclipped, plain mean'][1]:.3f}, "
          f"WLS with known NLF / oracle = "
          f"{base['pipeline, wls with known NLF'][1] / base['oracle: unclipped, plain mean'][1]:.3f}, "
          f"MLE / oracle = {base['censored MLE'][1] / base['oracle: unclipped, plain mean'][1]:.3f}")


if __name__ == "__main__":
    main()
