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

from dataclasses import dataclass

import numpy as np

from ..errors import DatasetError
from .capture import Sequence

PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


def planes(frames: np.ndarray) -> list[np.ndarray]:
    """The four 2x2-site planes of (..., H, W) frames (a mono sensor has four identical-statistics planes)."""
    return [frames[..., dy::2, dx::2] for dy, dx in PLANE_OFFSETS]


def temporal_mean_var(frames: np.ndarray) -> tuple[float, float]:
    """(mean, temporal variance) in DN and DN^2 of (n, h, w) frames of one plane.

    Variance: per-pixel variance over frames (ddof=1) after removing each
    frame's spatial mean, averaged over pixels; for n = 2 this is EMVA 1288's
    half variance of the difference image.
    """
    f = frames.astype(np.float64)
    fm = f.mean(axis=(1, 2), keepdims=True)
    mean = float(fm.mean())
    r = f - fm
    var = float(np.mean(np.var(r, axis=0, ddof=1)))
    return mean, var


@dataclass
class PlaneStats:
    """Temporal statistics of one sequence, per 2x2 site plane."""

    name: str
    kind: str
    exposure_s: float | None
    photons: float | None
    mean: np.ndarray  # (4,) DN
    var: np.ndarray  # (4,) DN^2
    n: int

    @property
    def mean_all(self) -> float:
        return float(self.mean.mean())

    @property
    def var_all(self) -> float:
        return float(self.var.mean())


def sequence_stats(seq: Sequence, frames: np.ndarray | None = None) -> PlaneStats:
    fr = seq.frames if frames is None else frames
    mv = np.array([temporal_mean_var(p) for p in planes(fr)])
    return PlaneStats(seq.name, seq.kind, seq.exposure_s, seq.photons, mv[:, 0], mv[:, 1], fr.shape[0])


@dataclass
class PTCFit:
    """Poisson-Gaussian photon-transfer fit: var = K_c * (mu - mu_dark) + var_dark, per plane.

    ``K`` pooled system gain (DN/e-), ``K_plane`` per plane, ``var_dark``
    temporal dark variance per plane (DN^2), ``mu_dark`` dark mean per plane (DN).
    """

    K: float
    K_plane: np.ndarray
    var_dark: np.ndarray
    mu_dark: np.ndarray
    points: list[PlaneStats]
    from_dark: bool


def fit_ptc(darks: list[PlaneStats], flats: list[PlaneStats]) -> PTCFit:
    """Fit K per plane (zero-intercept slope of the dark-corrected variance vs mean) and pooled.

    With darks the dark point is the average of the dark sequences; without, a
    line with intercept is fitted to the flats (intercept = dark variance at
    the black level ``mu_dark`` = NaN, unknown).
    """
    if not flats:
        raise DatasetError("photon transfer: no flat (or scene) sequence; expected at least one lit sequence")
    X = np.array([f.mean for f in flats])  # (m, 4)
    Y = np.array([f.var for f in flats])
    if darks:
        mu_d = np.mean([d.mean for d in darks], axis=0)
        var_d = np.mean([d.var for d in darks], axis=0)
        x, y = X - mu_d, Y - var_d
        K_plane = (x * y).sum(0) / (x * x).sum(0)
        K = float((x * y).sum() / (x * x).sum())
        return PTCFit(K, K_plane, var_d, mu_d, darks + flats, True)
    if len(flats) < 2:
        raise DatasetError("photon transfer: no dark sequence and a single flat; expected a dark sequence or >= 2 "
                           "flat levels to separate gain from read noise")
    K_plane, var_d = np.empty(4), np.empty(4)
    for c in range(4):
        K_plane[c], var_d[c] = np.polyfit(X[:, c], Y[:, c], 1)
    K = float(np.mean(K_plane))
    return PTCFit(K, K_plane, var_d, np.full(4, np.nan), list(flats), False)


# --------------------------------------------------------------------------- EMVA 1288

def _linear_b0(x, y):
    return float(np.sum(x * y) / np.sum(x * x))


def emva1288_numbers(seqs: list[Sequence]) -> dict | None:
    """EMVA 1288 K, sigma_d, DSNU1288 and PRNU1288 (reference-implementation procedure).

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
            sf = max(s_flats, key=lambda s: s.n)
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
