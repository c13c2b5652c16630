"""Statistics of measured and synthesised capture sequences, compared within their sampling error.

An independent check of a calibration: numpy only, no simcam code. Given the frames of a
sequence (n, H, W) in DN — measured (held out) and synthesised from the fitted profile at the same
ISO, exposure and clean level — :func:`sequence_stats` computes what a sensor engineer looks at,
each with its standard error, and :func:`compare` says which differ by more than ``z_max``
combined standard errors.

Statistics (per sequence):

* ``mean`` — the signal (DN);
* ``temporal_var`` — temporal variance per pixel, averaged over pixels (photon transfer);
* ``row_spread`` / ``col_spread`` — standard deviation of the row / column means of the temporal
  mean map (row and column fixed-pattern noise, plus their temporal part);
* ``pixel_spread`` — standard deviation of the temporal mean map after removing row and column
  means (DSNU / PRNU, hot pixels, plus temporal noise / n);
* ``outlier_fraction`` / ``outlier_level`` — share of the temporal-mean map's pixels beyond 8 robust
  sigma after removing row and column means (hot, dead, stuck pixels) and the median distance of
  those pixels (DN; only with 5 or more);
* ``tail_fraction`` — share of residuals (frame minus temporal mean) beyond 5 robust sigma (heavy
  tails, RTN, hot pixels blinking);
* ``code_nonuniformity`` — spread of the occupancy of adjacent codes relative to a smooth
  histogram (ADC differential non-linearity, coarse quantisation), per frame and averaged; about 1
  for a smooth law.

Standard errors use the textbook large-sample forms (variance of a sample variance
``2 s^4 / (m - 1)``, of a standard deviation ``s / sqrt(2 (m - 1))``, of a proportion
``p (1 - p) / m``), with the effective number of independent values stated at each statistic; the
mean and the temporal variance add the spread of their row and column averages, since row noise
and column patterns make the pixels of a row or a column dependent.
"""

from __future__ import annotations

import numpy as np


def _robust_sigma(x: np.ndarray) -> float:
    med = np.median(x)
    return float(1.4826 * np.median(np.abs(x - med)))


def _spread(x: np.ndarray) -> tuple[float, float]:
    """Standard deviation and its large-sample standard error ``s sqrt((kappa - 1) / (4 m))``, kappa the
    kurtosis (3 for a Gaussian: ``s / sqrt(2 m)``; a few hot pixels make it large, and one sensor's
    count of them a matter of chance)."""
    d = np.asarray(x, dtype=np.float64).ravel()
    d = d - d.mean()
    m2 = float(np.mean(d * d))
    if m2 <= 0:
        return 0.0, 0.0
    kappa = float(np.mean(d ** 4)) / (m2 * m2)
    s = float(np.sqrt(m2 * d.size / (d.size - 1)))
    return s, s * float(np.sqrt(max(kappa - 1.0, 0.0) / (4.0 * d.size)))


def sequence_stats(frames: np.ndarray) -> dict[str, tuple[float, float]]:
    """``{name: (value, standard error)}`` for one sequence of frames (n, H, W) in DN.

    The standard errors are closed forms over pixels, rows, columns or frames (module docstring):
    right where those are independent draws. A pattern with one random phase per frame for the
    whole sensor (a periodic pattern) makes every column of a frame move together, which they do
    not count (there the spread of the column means varies from capture to capture far more).
    """
    f = np.asarray(frames, dtype=np.float64)
    n, h, w = f.shape
    out: dict[str, tuple[float, float]] = {}
    m = f.mean(0)
    rows, cols = m.mean(1), m.mean(0)
    # noise shared along a row or a column (row noise, column FPN) makes pixels dependent: the
    # standard errors of the mean and of the temporal variance come from the spread of the row and
    # column averages (h and w values), not from h * w independent pixels
    se_mean = np.sqrt(rows.var(ddof=1) / h + cols.var(ddof=1) / w + f.var() / f.size)
    out["mean"] = (float(m.mean()), float(se_mean))
    tv = f.var(0, ddof=1)
    v = float(tv.mean())
    se_tv = np.sqrt(tv.mean(1).var(ddof=1) / h + tv.mean(0).var(ddof=1) / w + 2.0 * v * v / (h * w * (n - 1)))
    out["temporal_var"] = (v, float(se_tv))
    out["row_spread"] = _spread(rows)
    out["col_spread"] = _spread(cols)
    resid = m - rows[:, None] - cols[None, :] + m.mean()
    out["pixel_spread"] = _spread(resid)
    # outliers of the mean map (EMVA 1288 R4.0 sec. 8.5: defect pixels from the logarithmic
    # histogram of the mean image): the share beyond 8 robust sigma, and how far they lie
    # median profiles: a pixel stuck at white would lift its row and column means and make outliers of them
    rc = m - np.median(m, axis=1, keepdims=True)
    rc = rc - np.median(rc, axis=0, keepdims=True)
    rc = rc - np.median(rc)
    big = np.abs(rc) > 8.0 * max(_robust_sigma(rc), 1e-12)
    k = int(big.sum())
    out["outlier_fraction"] = (k / rc.size, float(np.sqrt(max(k, 1)) / rc.size))
    if k >= 5:
        lv = np.abs(rc[big])
        out["outlier_level"] = (float(np.median(lv)), float(1.2533 * 1.4826 * np.median(np.abs(lv - np.median(lv)))
                                                             / np.sqrt(k)))
    r = (f - m).ravel()
    s = _robust_sigma(r)
    p = float(np.mean(np.abs(r) > 5 * s)) if s > 0 else 0.0
    out["tail_fraction"] = (p, float(np.sqrt(max(p, 1.0 / r.size) * (1 - p) / r.size)))
    codes = np.rint(f).astype(np.int64).reshape(n, -1)
    lo, hi = (int(v) for v in np.percentile(codes, [5, 95]))
    if hi - lo + 1 >= 8:
        # per frame: a frame's pixels are independent draws of the law (its fixed pattern included), so
        # its code counts are multinomial and q ~ chi^2_k / k about 1 for a smooth law; pooling the frames
        # would not be (a pixel's frames fall on nearby codes where a fixed pattern dominates)
        qs = []
        for fr in codes:
            # codes lo - 2 .. hi + 2, so that the 5-code running mean of every code in lo .. hi is whole
            counts = np.bincount(np.clip(fr - lo + 3, 0, hi - lo + 6), minlength=hi - lo + 7)[1:-1].astype(np.float64)
            smooth = np.convolve(counts, np.ones(5) / 5, mode="same")[2:-2]
            counts = counts[2:-2]
            ok = smooth > 0
            dev = (counts[ok] - smooth[ok]) / np.sqrt(smooth[ok])
            qs.append(float(np.mean(dev * dev)))
        q = float(np.mean(qs))
        k = hi - lo + 1
        # one frame's standard error (the frames share their fixed pattern, so their mean is not
        # n times better), a non-central chi^2's: var = (2 k + 4 lambda) / k^2 with lambda = k (q - 1)
        out["code_nonuniformity"] = (q, float(np.sqrt((2.0 + 4.0 * max(q - 1.0, 0.0)) / k)))
    return out


def dark_slope(dark_means: list[tuple[float, float]]) -> tuple[float, float]:
    """Dark signal per second (DN/s) and its standard error from (exposure_s, mean) of two exposures or more."""
    t = np.array([a for a, _ in dark_means])
    y = np.array([b for _, b in dark_means])
    if t.size < 2 or np.ptp(t) == 0:
        raise ValueError("dark_slope: expected darks at two exposure times or more")
    a, b = np.polyfit(t, y, 1)
    resid = y - (a * t + b)
    dof = max(t.size - 2, 1)
    se = float(np.sqrt((resid @ resid) / dof / ((t - t.mean()) @ (t - t.mean())))) if t.size > 2 else 0.0
    return float(a), se


def compare(measured: dict[str, tuple[float, float]], synthesised: dict[str, tuple[float, float]], *,
            z_max: float = 5.0, rel_floor: float = 0.0) -> list[dict]:
    """Rows ``{stat, measured, synthesised, z, ok}``; ``ok`` when ``|difference| <= z_max`` combined
    standard errors (+ ``rel_floor`` of the measured value, for a stated model tolerance)."""
    rows = []
    for k in measured:
        if k not in synthesised:
            continue
        (a, sa), (b, sb) = measured[k], synthesised[k]
        se = float(np.hypot(sa, sb))
        tol = z_max * se + rel_floor * abs(a)
        z = (b - a) / se if se > 0 else (0.0 if a == b else np.inf)
        rows.append({"stat": k, "measured": a, "synthesised": b, "z": float(z), "ok": bool(abs(b - a) <= tol)})
    return rows
