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
  means (DSNU / PRNU, plus temporal noise / n);
* ``tail_fraction`` — share of residuals (frame minus temporal mean) beyond 5 robust sigma (heavy
  tails, RTN, hot pixels blinking);
* ``code_nonuniformity`` — spread of the occupancy of adjacent codes relative to a smooth
  histogram (ADC differential non-linearity, coarse quantisation).

Standard errors use the textbook large-sample forms (variance of a sample variance
``2 s^4 / (m - 1)``, of a standard deviation ``s / sqrt(2 (m - 1))``, of a proportion
``p (1 - p) / m``), with the effective number of independent values stated at each statistic.
"""

from __future__ import annotations

import numpy as np


def _robust_sigma(x: np.ndarray) -> float:
    med = np.median(x)
    return float(1.4826 * np.median(np.abs(x - med)))


def sequence_stats(frames: np.ndarray) -> dict[str, tuple[float, float]]:
    """``{name: (value, standard error)}`` for one sequence of frames (n, H, W) in DN."""
    f = np.asarray(frames, dtype=np.float64)
    n, h, w = f.shape
    out: dict[str, tuple[float, float]] = {}
    m = f.mean(0)
    out["mean"] = (float(m.mean()), float(f.std() / np.sqrt(f.size)))
    tv = f.var(0, ddof=1)
    v = float(tv.mean())
    out["temporal_var"] = (v, float(v * np.sqrt(2.0 / (h * w * (n - 1)))))
    rows, cols = m.mean(1), m.mean(0)
    rs, cs = float(rows.std(ddof=1)), float(cols.std(ddof=1))
    out["row_spread"] = (rs, rs / np.sqrt(2.0 * (h - 1)))
    out["col_spread"] = (cs, cs / np.sqrt(2.0 * (w - 1)))
    resid = m - rows[:, None] - cols[None, :] + m.mean()
    ps = float(resid.std(ddof=1))
    out["pixel_spread"] = (ps, ps / np.sqrt(2.0 * (h * w - 1)))
    r = (f - m).ravel()
    s = _robust_sigma(r)
    p = float(np.mean(np.abs(r) > 5 * s)) if s > 0 else 0.0
    out["tail_fraction"] = (p, float(np.sqrt(max(p, 1.0 / r.size) * (1 - p) / r.size)))
    codes = np.rint(f).astype(np.int64).ravel()
    lo, hi = np.percentile(codes, [5, 95])
    counts = np.bincount(codes - codes.min())[int(lo - codes.min()):int(hi - codes.min()) + 1].astype(np.float64)
    if counts.size >= 8 and counts.sum() > 0:
        smooth = np.convolve(counts, np.ones(5) / 5, mode="same")
        ok = smooth > 0
        dev = (counts[ok] - smooth[ok]) / np.sqrt(smooth[ok])  # ~ N(0, 1) per code for a smooth law
        q = float(np.mean(dev * dev))
        out["code_nonuniformity"] = (q, float(np.sqrt(2.0 / ok.sum())))
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
