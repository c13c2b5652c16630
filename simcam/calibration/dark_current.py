"""Dark current from dark sequences at several exposure times (one ISO), whole frames.

The mean dark signal grows with the exposure time t as ``mu_dark(t) = mu_dark(0) + K mu_I t`` and the
dark temporal variance as ``sigma_dark^2(t) = sigma_dark^2(0) + K^2 mu_I t`` (dark electrons are
Poisson): EMVA Standard 1288 Release 4.0, the dark-current evaluation from the dark signal and the
dark variance against exposure time. Both slopes are least-squares lines over the exposure times
of the dark sequences' whole-frame statistics (:class:`simcam.calibration.capture.FrameSummary`),
so ``mu_I`` (e-/s) comes twice: from the mean (needs a stable black level) and from the variance
(needs no black level; the temporal variance of each exposure is half the variance of its first
frame pair's difference, as EMVA 1288 computes it). Its non-uniformity is the spatial standard
deviation of the per-pixel least-squares slope of the temporal-mean images against exposure time,
its variance corrected by the temporal noise the slope carries (``sum c_i^2 s2_i / L_i`` with
``c_i`` the slope weights, ``s2_i`` the temporal variance and ``L_i`` the frames of exposure i).
"""

from __future__ import annotations

import numpy as np

from .capture import Sequence


def dark_current(darks: list[Sequence], K: float | None) -> dict:
    """Dark current of one ISO's dark sequences.

    Parameters
    ----------
    darks : dark sequences (their exposure times and whole-frame statistics are used).
    K : system gain in DN/e- (None or 0 when not measured: results stay in DN/s).

    Returns
    -------
    dict
        ``{"applicable": False, "reason": ...}`` when fewer than two exposure times are given;
        else the exposure times (s), the mean dark signal (DN) and temporal variance (DN^2) at each,
        the slopes ``dn_per_s`` and ``dn2_per_s``, ``e_per_s_from_mean`` and ``e_per_s_from_variance``
        (None without K) and the non-uniformity ``nonuniformity_dn_per_s`` / ``nonuniformity_e_per_s``.
    """
    with_t = [s for s in darks if s.exposure_s is not None]
    pairs = [s for s in with_t if s.n == 2]
    if len({float(s.exposure_s) for s in pairs}) >= 2:  # EMVA 1288 temporal darks (frame pairs): those alone
        with_t = pairs
    times = sorted({float(s.exposure_s) for s in with_t})
    if len(times) < 2:
        why = ("no dark sequence" if not darks else "dark exposure times not given" if not with_t
               else f"darks at a single exposure time ({times[0]:.4g} s)")
        return {"applicable": False, "reason": f"needs darks at >= 2 exposure times: {why}"}
    mean, var, nframes = [], [], []
    for t in times:
        st = [s.stats() for s in with_t if float(s.exposure_s) == t]
        w = np.array([x.n for x in st], dtype=np.float64)
        mean.append(float(np.average([x.avg_mean[4] for x in st], weights=w)))
        var.append(float(np.average([x.pair_var[4] for x in st], weights=w)))
        nframes.append(int(w.sum()))
    t = np.asarray(times)
    slope_m, icpt_m = np.polyfit(t, mean, 1)
    slope_v, icpt_v = np.polyfit(t, var, 1)
    good_k = K is not None and np.isfinite(K) and K > 0
    out = {"applicable": True, "exposure_s": times, "frames": nframes, "mean_dn": mean, "temporal_var_dn2": var,
           "dn_per_s": float(slope_m), "dn2_per_s": float(slope_v), "dark_dn_at_0s": float(icpt_m),
           "dark_var_dn2_at_0s": float(icpt_v),
           "e_per_s_from_mean": float(slope_m / K) if good_k else None,
           "e_per_s_from_variance": float(slope_v / K ** 2) if good_k else None,
           "nonuniformity_dn_per_s": None, "nonuniformity_e_per_s": None, "nonuniformity_reason": None}
    maps, noise = [], []  # per exposure time: frame-weighted temporal-mean image, its temporal noise variance
    for t_ in times:
        st = [x.stats() for x in with_t if float(x.exposure_s) == t_]
        if any(x.mean_map is None for x in st):
            out["nonuniformity_reason"] = "temporal-mean images of the darks not kept"
            return out
        w = np.array([x.n for x in st], dtype=np.float64)
        maps.append(sum(wi * x.mean_map.astype(np.float64) for wi, x in zip(w, st)) / w.sum())
        noise.append(float(np.average([x.temporal_var[4] for x in st], weights=w)) / w.sum())
    c = (t - t.mean()) / np.sum((t - t.mean()) ** 2)  # per-pixel least-squares slope weights
    slope = sum(ci * m for ci, m in zip(c, maps))
    s2 = float(np.var(slope, ddof=1)) - float(np.sum(c ** 2 * np.asarray(noise)))
    if s2 <= 0:
        out["nonuniformity_dn_per_s"] = 0.0
        out["nonuniformity_reason"] = "below the temporal noise of the mean images (set to 0)"
    else:
        out["nonuniformity_dn_per_s"] = float(np.sqrt(s2))
    if good_k:
        out["nonuniformity_e_per_s"] = out["nonuniformity_dn_per_s"] / K
    return out


#: How many standard errors the dark variance's rise may fall short of K times the dark level's before the
#: rise is not taken for Poisson charge (:func:`series_fit`)
POISSON_Z = 3.0


def series_fit(series: list, K: float | None) -> dict | None:
    """Dark current of dark frame stacks at several exposure times (the loop's ``CaptureData.dark_series``).

    ``series``: (exposure_s, (n, H, W) frames in DN) per dark sequence; ``K``: the system gain (DN/e-;
    None or <= 0: taken from the darks themselves, variance slope / mean slope, the dark current
    being Poisson). Returns None with fewer than two exposure times, else the slopes of the mean dark
    level (DN/s) and of the temporal variance (DN^2/s) against exposure time, the gain used, the
    mean rate (e-/s, from the mean's slope; from the variance's where the variance's rise falls short of K
    times the mean's by more than :data:`POISSON_Z` standard errors and by more than half: ``poisson_z``,
    ``non_poisson_dn_per_s``, the slopes' standard errors ``dn_per_s_se`` and ``dn2_per_s_se``) and the
    spread of the per-pixel rate: the log-normal
    ``log_sigma`` whose interquartile range over median, with the temporal noise the slope carries,
    is that of the per-pixel least-squares slopes of the temporal-mean images (row and column
    profiles removed: they are not pixel dark current; :func:`lognormal_log_sigma`).
    """
    from .diagnostics import exposure_slope, remove_profiles, robust_sigma

    by_t: dict[float, list] = {}
    for t, f in series:
        by_t.setdefault(float(t), []).append(f)
    times = sorted(by_t)
    if len(times) < 2:
        return None
    mean, var, maps, noise, var_maps, level_var = [], [], [], [], [], []
    for t in times:
        stacks = [f.astype(np.float64) for f in by_t[t]]
        n = np.array([s.shape[0] for s in stacks], dtype=np.float64)
        mean.append(float(np.average([s.mean() for s in stacks], weights=n)))
        pv = [np.var(s, axis=0, ddof=1) for s in stacks]  # per-pixel temporal variance (NaN for one frame)
        v = float(np.average([np.mean(p) for p in pv], weights=n))
        var.append(v)
        m = n > 1
        var_maps.append(sum(ni * p for ni, p, ok in zip(n, pv, m) if ok) / max(n[m].sum(), 1))
        del pv
        maps.append(sum(ni * s.mean(0) for ni, s in zip(n, stacks)) / n.sum())
        noise.append(v / n.sum())
        # what all pixels of a frame share (a frame's offset) does not average out over the pixels: the
        # sampling variance of the sequence's level from the scatter of its frame means about a line in
        # the frame index (a drift over the sequence is not sampling noise of its level)
        level_var.append(_level_variance([s.reshape(s.shape[0], -1).mean(axis=1) for s in stacks]))
    t = np.asarray(times)
    raw, c = exposure_slope(times, maps)  # per-pixel least-squares slope (DN/s)
    # hot pixels whose charge grows with the exposure are no dark current of the array: slopes beyond
    # 10 robust sigma above the median are left out of the mean slope (the mean over the others)
    keep = raw <= np.median(raw) + 10 * robust_sigma(raw)
    nk = max(int(keep.sum()), 1)
    slope_m = float(raw[keep].mean())
    slope_v = float(np.polyfit(t, var, 1)[0])
    se_m = float(np.sqrt(np.var(raw[keep]) / nk + np.sum(c ** 2 * np.asarray(level_var))))
    # the variance's slope over the same pixels as the mean's, with its standard error
    if all(np.ndim(vm) == 2 for vm in var_maps):
        slope_vk = float(sum(ci * float(vm[keep].mean()) for ci, vm in zip(c, var_maps)))
        se_v = float(np.sqrt(np.sum([ci ** 2 * float(np.var(vm[keep])) / nk for ci, vm in zip(c, var_maps)])))
    else:  # an exposure time with single frames only: no temporal variance to compare
        slope_vk, se_v = slope_v, 0.0
    measured_k = K is not None and np.isfinite(K) and K > 0
    gain = float(K) if measured_k else (slope_v / slope_m if slope_m > 0 else 0.0)
    # Poisson charge raises the dark variance by K times the dark level's rise (EMVA 1288's mean and
    # variance methods agree). A level that rises without it (a black level drifting with the exposure
    # time or over the capture) is not dark current: where the variance slope falls short of K times the
    # mean slope by more than POISSON_Z standard errors and by more than half, the rate is the
    # variance method's (the Poisson part alone) and the rest of the rise is reported, not modelled.
    se = float(np.hypot(se_v, gain * se_m))
    z = (slope_vk - gain * slope_m) / se if measured_k and se_v > 0 else 0.0  # (a gain from the darks: no test)
    poisson_m = slope_m
    if gain > 0 and slope_m > 0 and z < -POISSON_Z and slope_vk < 0.5 * gain * slope_m:
        poisson_m = max(slope_vk, 0.0) / gain
    slope_map = remove_profiles(raw)[keep] + float(np.median(raw)) - (slope_m - poisson_m)
    noise_sd = float(np.sqrt(np.sum(c ** 2 * np.asarray(noise))))
    log_sigma = lognormal_log_sigma(slope_map, poisson_m, noise_sd) if poisson_m > 0 else 0.0
    return {"exposure_s": times, "mean_dn": mean, "temporal_var_dn2": var, "dn_per_s": slope_m,
            "dn2_per_s": slope_v, "dn_per_s_se": se_m, "dn2_per_s_se": se_v, "poisson_z": float(z),
            "gain_dn_per_e": gain, "e_per_s": poisson_m / gain if gain > 0 else 0.0,
            "non_poisson_dn_per_s": float(slope_m - poisson_m), "log_sigma": float(log_sigma)}


def _level_variance(frame_means: list) -> float:
    """Sampling variance of the mean level of sequences with these frame means: each sequence's residual
    variance about a least-squares line in the frame index (n - 2 degrees of freedom), pooled, over the
    frames in all; 0 where no sequence has 3 frames."""
    ss, dof, n = 0.0, 0, 0
    for fm in frame_means:
        fm = np.asarray(fm, dtype=np.float64)
        n += fm.size
        if fm.size >= 3:
            i = np.arange(fm.size, dtype=np.float64)
            ss += float(np.sum((fm - np.polyval(np.polyfit(i, fm, 1), i)) ** 2))
            dof += fm.size - 2
    return ss / dof / n if dof else 0.0


def _spread(x: np.ndarray) -> float:
    q25, q50, q75 = np.percentile(x, [25, 50, 75])
    return float((q75 - q25) / q50) if q50 > 0 else np.inf


def lognormal_log_sigma(values: np.ndarray, mean: float, noise_sd: float = 0.0) -> float:
    """The log-spread of the log-normal law of ``mean`` which, plus Gaussian noise of ``noise_sd``,
    has the ``values``' interquartile range relative to their median, (q75 - q25) / q50: solved by
    matching that statistic on a fixed sample of the law (indirect inference).

    For a log-normal (q75 - q25) / q50 = 2 sinh(0.6745 sigma), increasing in sigma and untouched by a
    few hot pixels; the robust standard deviation (1.4826 MAD) is not a log-normal's standard deviation
    (it reads sigma = 0.4 as 0.345) and stops growing near sigma = 0.9.

    Parameters
    ----------
    values : ndarray
        The per-pixel values (DN/s: the dark-signal slopes), centred on their median level.
    mean : float
        Mean of the law, same unit.
    noise_sd : float
        Standard deviation of the Gaussian noise on each value.

    Returns
    -------
    float
        sigma of log(value), in [0, 3]; 0 when the spread is within the noise.

    Examples
    --------
    >>> import numpy as np
    >>> x = 20.0 * np.random.default_rng(1).lognormal(-0.08, 0.4, 400_000)  # mean 20, log-sigma 0.4
    >>> round(lognormal_log_sigma(x, 20.0), 2)
    0.4
    """
    from scipy.optimize import brentq

    target = _spread(np.asarray(values, dtype=np.float64).ravel())
    rng = np.random.default_rng(0)
    z, w = rng.standard_normal(200_000), rng.standard_normal(200_000)

    def excess(s: float) -> float:
        return _spread(mean * np.exp(s * z - 0.5 * s * s) + noise_sd * w) - target

    if mean <= 0 or not np.isfinite(target) or excess(0.0) >= 0:
        return 0.0
    if excess(3.0) <= 0:
        return 3.0
    return float(brentq(excess, 0.0, 3.0, xtol=1e-4))
