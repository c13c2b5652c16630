"""The residual battery's per-pixel kernels (:mod:`simcam.calibration.pixelwise`) against the numpy forms
they replace: median over frames and the two-level (telegraph) split, on 16 frames x 384 x 512 integer
codes, and the 5 x 5 running median of one CFA plane against scipy's ``median_filter``. Prints the CPU
model and the median of 7 runs of each.

Usage::

    python benchmarks/pixelwise.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from scipy.ndimage import median_filter

from simcam.calibration.pixelwise import median_box, temporal_median, two_level_split

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/machine.py
from machine import cpu_model  # noqa: E402


def _numpy_two_level(v, sigma2, min_level=2):
    n = v.shape[0]
    s = np.sort(v, axis=0)
    cs, cs2 = np.cumsum(s, 0), np.cumsum(s * s, 0)
    tot, tot2 = cs[-1], cs2[-1]
    best = np.full(v.shape[1:], np.inf)
    gap = np.zeros(v.shape[1:])
    for k in range(min_level, n - min_level + 1):
        a, a2 = cs[k - 1], cs2[k - 1]
        b, b2 = tot - a, tot2 - a2
        w = (a2 - a * a / k) + (b2 - b * b / (n - k))
        better = w < best
        best = np.where(better, w, best)
        gap = np.where(better, b / (n - k) - a / k, gap)
    return gap


def _median_time(fn, reps=7):
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))


def main() -> None:
    x = np.round(np.random.default_rng(0).normal(100, 3, (16, 384, 512))).astype(np.float32)
    v = x.reshape(16, -1).astype(np.float64)
    temporal_median(x[:, :2, :2])
    two_level_split(v[:, :4], 9.0)  # compile
    plane = x[0, 0::2, 0::2].astype(np.float64) + np.random.default_rng(1).normal(0, 1, (192, 256))
    median_box(plane[:8, :8])
    print(f"CPU: {cpu_model()}")
    print("| kernel | numpy (ms) | simcam (ms) | ratio |")
    print("|---|---|---|---|")
    for name, ref, new in (
            ("median over 16 frames", lambda: np.median(x.astype(np.float64), axis=0), lambda: temporal_median(x)),
            ("two-level split", lambda: _numpy_two_level(v, 9.0), lambda: two_level_split(v, 9.0)),
            ("5 x 5 running median of a 192 x 256 plane (scipy median_filter)",
             lambda: median_filter(plane, size=5, mode="nearest"), lambda: median_box(plane, 5))):
        a, b = _median_time(ref), _median_time(new)
        print(f"| {name} | {1e3 * a:.1f} | {1e3 * b:.1f} | {b / a:.2f} |")


if __name__ == "__main__":
    main()
