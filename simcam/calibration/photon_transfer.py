"""Photon transfer: temporal mean and variance of frame sequences, system gain, EMVA 1288 figures.

Temporal variance is taken from frames with each frame's own mean removed
(for a pair: half the variance of the difference, EMVA 1288 R3.0 eq. 26), so
a global per-frame offset or gain jitter does not inflate it.

EMVA numbers follow the reference implementation (PyPI ``emva1288``,
``process/results.py``): K is the zero-intercept least-squares slope of
(s2_y - s2_ydark) against (mu_y - mu_ydark) over the points up to 70 % of the
saturation mean; the saturation point is the maximum of the variance curve;
sigma_y.dark is the intercept of a linear fit of s2_ydark against exposure
time (a single value when there are <= 2 exposure times), floored at 0.24 DN^2;
sigma_d = sqrt(sigma_y.dark^2 - 1/12) / K; DSNU1288 and PRNU1288 from the
spatial variance of the L-frame averages corrected by the temporal variance / L.
"""

from __future__ import annotations


import numpy as np

from .capture import Sequence

PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


def plane_ptc(darks: list[np.ndarray], flats: list[np.ndarray], full_scale_dn: float) -> dict | None:
    """Per-CFA-plane photon transfer (NLF) from ``(4, 2)`` (mean, temporal variance) points per sequence.

    var = K_c * (mu - mu_dark_c) + var_dark_c with K_c the zero-intercept slope of the
    dark-corrected points (or, without darks, a line with intercept); returned also as the
    NLF on normalised raw, beta1_c = K_c / full_scale, beta2_c = var_dark_c / full_scale^2
    (Abdelhamed, PhD dissertation, York University, 2020, eq. 3.8). None without a lit sequence.
    """
    if not flats:
        return None
    X = np.array([f[:, 0] for f in flats])
    Y = np.array([f[:, 1] for f in flats])
    if darks:
        mu0 = np.mean([d[:, 0] for d in darks], axis=0)
        v0 = np.mean([d[:, 1] for d in darks], axis=0)
        x, y = X - mu0, Y - v0
        K = (x * y).sum(0) / (x * x).sum(0)
    elif len(flats) >= 2:
        fits = np.array([np.polyfit(X[:, c], Y[:, c], 1) for c in range(4)])
        K, v0, mu0 = fits[:, 0], fits[:, 1], np.full(4, np.nan)
    else:
        return None
    return {"K_dn_per_e": K.tolist(), "var_dark_dn2": np.asarray(v0).tolist(), "mu_dark_dn": np.asarray(mu0).tolist(),
            "nlf_beta1": (K / full_scale_dn).tolist(), "nlf_beta2": (np.asarray(v0) / full_scale_dn ** 2).tolist()}


# --------------------------------------------------------------------------- EMVA 1288

def _linear_b0(x, y):
    return float(np.sum(x * y) / np.sum(x * x))


def emva1288_numbers(seqs: list[Sequence]) -> dict | None:
    """EMVA 1288 numbers of a capture set: for a CFA sensor computed on each 2x2-site plane
    (EMVA 1288 evaluates each colour channel on its own) and averaged, with the per-plane
    values under ``"planes"``; for a monochrome sensor on the whole image."""
    if not seqs or seqs[0].cfa is None:
        return emva1288_mono(seqs)
    import dataclasses

    per = []
    for dy, dx in PLANE_OFFSETS:
        sub = [dataclasses.replace(s, frames=s.frames[:, dy::2, dx::2]) for s in seqs]
        per.append(emva1288_mono(sub))
    if any(p is None for p in per):
        return None
    out = {}
    for k in ("K_dn_per_e", "sigma_dark_e", "sigma_y_dark_dn", "dsnu_e", "prnu_percent"):
        vals = [p[k] for p in per]
        out[k] = None if any(v is None for v in vals) else float(np.mean(vals))
    out["planes"] = per
    return out


def emva1288_mono(seqs: list[Sequence]) -> dict | None:
    """EMVA 1288 K, sigma_d, DSNU1288 and PRNU1288 of one channel (reference-implementation procedure).

    Temporal points: every dark/flat sequence with exactly 2 frames; each flat
    is paired with the dark of the same exposure time (else the dark of the
    nearest exposure). Spatial: the dark and flat sequences with > 2 frames
    (the longest of each). If no 2-frame sequences exist, the first two frames
    of every sequence are used as the temporal pair. Returns None when there is
    no dark or fewer than two flats.

    Returns
    -------
    dict with ``K_dn_per_e``, ``sigma_dark_e``, ``sigma_y_dark_dn``, ``dsnu_e``,
    ``prnu_percent`` (None where the data does not allow), ``fit_index_max``,
    ``saturation_index``.
    """
    darks = [s for s in seqs if s.kind == "dark"]
    flats = [s for s in seqs if s.kind == "flat"]
    if not darks or len(flats) < 2:
        return None
    t_darks = [s for s in darks if s.n == 2] or darks
    t_flats = [s for s in flats if s.n == 2] or flats

    def stats(s):
        fr = s.frames[:2].astype(np.float64)
        mu = float(fr.mean())
        d = fr[0] - fr[1]
        return mu, float(np.mean((d - d.mean()) ** 2) / 2)

    dark_t = {}
    for s in t_darks:
        dark_t[s.exposure_s or 0.0] = stats(s)
    texp = np.array(sorted(dark_t))
    u_yd_all = np.array([dark_t[t][0] for t in texp])
    s2_yd_all = np.array([dark_t[t][1] for t in texp])
    u_y, s2_y, u_yd, s2_yd = [], [], [], []
    for s in t_flats:
        t = s.exposure_s or 0.0
        j = int(np.argmin(np.abs(texp - t)))
        mu, var = stats(s)
        u_y.append(mu)
        s2_y.append(var)
        u_yd.append(u_yd_all[j])
        s2_yd.append(s2_yd_all[j])
    u_y, s2_y, u_yd, s2_yd = map(np.array, (u_y, s2_y, u_yd, s2_yd))
    order = np.argsort([s.photons if s.photons is not None else (s.exposure_s or 0) for s in t_flats], kind="stable")
    u_y, s2_y, u_yd, s2_yd = u_y[order], s2_y[order], u_yd[order], s2_yd[order]
    # saturation: maximum of the variance curve, scanned backwards (reference implementation)
    max_, isat = 0.0, 0
    for i in range(len(s2_y) - 1, -1, -1):
        if s2_y[i] >= max_ or s2_y[abs(i - 1)] >= max_:
            max_, isat = s2_y[i], i
        elif s2_y[i] < max_ and s2_y[abs(i - 1)] < max_:
            break
    Y = u_y - u_yd
    imax = int(np.max(np.argwhere(Y <= 0.7 * Y[isat])))
    sl = slice(0, imax + 1)
    K = _linear_b0(Y[sl], (s2_y - s2_yd)[sl])
    if len(texp) <= 2:
        s2_dark = float(s2_yd_all[0])
    else:
        s2_dark = float(np.polyfit(texp, s2_yd_all, 1)[1])
    s2_dark = max(s2_dark, 0.24)
    sigma_y_dark = np.sqrt(s2_dark)
    sigma_d = float(np.sqrt(s2_dark - 1.0 / 12.0) / K)
    out = {"K_dn_per_e": K, "sigma_dark_e": sigma_d, "sigma_y_dark_dn": float(sigma_y_dark),
           "dsnu_e": None, "prnu_percent": None, "fit_index_max": imax, "saturation_index": isat}
    s_darks = [s for s in darks if s.n > 2]
    s_flats = [s for s in flats if s.n > 2 and s.saturated_fraction() <= 0.01]
    if s_darks:
        sd = max(s_darks, key=lambda s: s.n)
        avg_d, s2_d = _spatial(sd.frames)
        if s2_d >= 0:
            out["dsnu_e"] = float(np.sqrt(s2_d) / K)
        if s_flats:
            sf = max(s_flats, key=lambda s: (s.n, float(s.frames.mean())))
            avg_f, s2_f = _spatial(sf.frames)
            if s2_f - s2_d >= 0:
                out["prnu_percent"] = float(np.sqrt(s2_f - s2_d) * 100 / (avg_f.mean() - avg_d.mean()))
    return out


def _spatial(frames: np.ndarray) -> tuple[np.ndarray, float]:
    """(average image, spatial variance corrected for the temporal variance / L)."""
    f = frames.astype(np.float64)
    L = f.shape[0]
    avg = f.mean(0)
    s2_meas = float(np.var(avg, ddof=1))
    stack = float(np.mean(np.var(f, axis=0, ddof=1)))
    return avg, s2_meas - stack / L
