"""Abdelhamed 2020, fig. 5.9: robust mean estimators under clipping, against the number of frames and beta1.

Truth: a synthetic scene (values 0..1, so both ends clip) on a 256 x 256 mosaic; noise from
the NLF (Abdelhamed 2020, eq. 5.2, beta2 = beta1 / 100) and clipping to [0, 1] (eq. 5.3). Methods: WLS
fit of the CDF (closed form and the exact eq. 5.10 minimiser), censored MLE, the plain mean of
the clipped samples, and the oracle: the plain mean of the same samples before clipping.
MSE is reported over all pixels and over the pixels with at least one clipped sample, and
on those by the fraction of clipped samples (the information a censored estimator has left).
A truth at the clip point clips half its samples; a truth beyond it is not identifiable
(every sample clipped: the fit falls back and flags the pixel invalid), so the scene stays in [0, 1].

Run: python experiments/fig5_9_robust_mean.py [--out experiments/out]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's simcam, not an installed one
from simcam.groundtruth import SyntheticBurst, censored_mle, plain_mean, wls_cdf_fit

METHODS = ("wls", "wls_exact", "mle", "mean", "oracle")


def run(truth: np.ndarray, n: int, beta1: float, seed: int) -> dict:
    rng = np.random.default_rng(np.random.SeedSequence([seed, n, int(beta1 * 1e9)]))
    y = truth.ravel()
    sd = np.sqrt(beta1 * np.clip(y, 0, None) + beta1 / 100)
    raw = (y + sd * rng.standard_normal((n, y.size))).astype(np.float32)
    x = np.clip(raw, 0, 1)
    w = wls_cdf_fit(x)
    est = {
        "wls": w.mu,
        "wls_exact": wls_cdf_fit(x, refine=3).mu,
        "mle": censored_mle(x).mu,
        "mean": plain_mean(x).mu,
        "oracle": raw.mean(0),
    }
    clipped = ((x <= 0) | (x >= 1)).any(0) & w.valid
    frac = ((x <= 0) | (x >= 1)).mean(0)
    out = {}
    for k, v in est.items():
        e2 = (v.astype(np.float64) - y) ** 2
        out[k] = (e2.mean(), e2[clipped].mean(), [np.mean(e2[clipped & (frac > a) & (frac <= b)]) if
                                                   np.any(clipped & (frac > a) & (frac <= b)) else np.nan
                                                   for a, b in ((0, 0.1), (0.1, 0.3), (0.3, 0.6))])
    out["clipped_fraction"] = clipped.mean()
    out["invalid"] = int((~w.valid).sum())
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="experiments/out")
    ap.add_argument("--size", type=int, default=256)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth = SyntheticBurst(shape=(args.size, args.size), n=1, drift_px=0.0, level=(0.0, 1.0), cell=4.0, seed=11).truth(0)

    ns = [5, 10, 20, 50, 100, 150]
    betas = [1e-4, 3e-4, 1e-3, 3e-3, 1e-2]
    res_n = {n: run(truth, n, 1e-3, 1) for n in ns}
    res_b = {b: run(truth, 50, b, 2) for b in betas}

    def table(title, keys, res, fmt):
        print(title)
        print(f"{'':>8} " + " ".join(f"{m:>11}" for m in METHODS) + "   (MSE all px | clipped px), x1e-6")
        for k in keys:
            r = res[k]
            print(f"{fmt(k):>8} " + " ".join(f"{r[m][0] * 1e6:5.2f}|{r[m][1] * 1e6:5.2f}" for m in METHODS)
                  + f"   clipped {r['clipped_fraction'] * 100:.1f} %, fallback {r['invalid']} px")
        print("WLS / oracle on clipped pixels: " + ", ".join(f"{fmt(k)}: {res[k]['wls'][1] / res[k]['oracle'][1]:.2f}"
                                                            for k in keys))
        print("  by censored fraction (0-10 %, 10-30 %, 30-60 %): " + "; ".join(
            f"{fmt(k)}: " + "/".join(f"{a / b:.2f}" for a, b in zip(res[k]['wls'][2], res[k]['oracle'][2]))
            for k in keys))
        print("MLE / oracle on clipped pixels: " + ", ".join(f"{fmt(k)}: {res[k]['mle'][1] / res[k]['oracle'][1]:.2f}"
                                                            for k in keys))

    table("(a) beta1 = 1e-3, against the number of frames", ns, res_n, str)
    table("(b) N = 50, against beta1", betas, res_b, lambda b: f"{b:.0e}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    styles = {"wls": ("WLS CDF fit (closed form)", "C0", "-o"), "wls_exact": ("WLS CDF fit (exact eq. 5.10)", "C9", ":x"),
              "mle": ("censored MLE", "C1", "-s"), "mean": ("plain mean (clipped)", "C2", "-^"),
              "oracle": ("mean before clipping (oracle)", "k", "--")}
    for col, (keys, res, xlabel, logx) in enumerate(((ns, res_n, "number of frames N (beta1 = 1e-3)", False),
                                                     (betas, res_b, "beta1 (N = 50)", True))):
        for row, (idx, what) in enumerate(((0, "all pixels"), (1, "pixels with clipped samples"))):
            ax = axes[row, col]
            for m in METHODS:
                lab, c, st = styles[m]
                ax.plot(keys, [res[k][m][idx] for k in keys], st, color=c, label=lab)
            ax.set_yscale("log")
            if logx:
                ax.set_xscale("log")
            ax.set_xlabel(xlabel)
            ax.set_ylabel(f"MSE ({what})")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Robust mean under clipping (Abdelhamed 2020, fig. 5.9 set-up)")
    fig.tight_layout()
    fig.savefig(out / "fig5_9_robust_mean.png", dpi=110)
    print(f"wrote {out / 'fig5_9_robust_mean.png'}")


if __name__ == "__main__":
    main()
