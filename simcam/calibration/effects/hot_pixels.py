"""``hot_pixels``: a fixed set of pixels with a large extra dark signal.

Physics. Lattice defects make a few pixels collect far more dark current than the rest: a fixed set
(``fraction`` of the pixels, drawn once per sensor) with offsets spread over orders of magnitude,
the tail of the dark-signal histogram (EMVA 1288 Release 4.0, sec. 4: defect pixels, and sec. 8:
the logarithmic histograms that show them; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*,
PhD dissertation, York University, 2020, ch. 2, defective pixels). The loop models the offsets as a
log-normal in DN; with them the pixel marginal is no longer Gaussian (no closed-form density).

Fit. Pixels whose dark temporal *median* and temporal *mean* (row / column profiles removed) are
both above 6 robust sigma (:func:`~simcam.calibration.diagnostics.hot_pixel_mask`: a heavy-tailed
read-noise outlier lifts one frame, a hot pixel every frame); their ``fraction``, ``count``, and a
log-normal of their offsets in the dark mean map by the moments of the log offsets (``log_mean``,
``log_sigma``).

A log-normal is an approximation of whatever law the offsets follow (dark-current outliers are
often closer to exponential): it is fitted to the *detected* part, offsets above the threshold
(~6 x the map's noise), which is all the data says about them; smaller offsets are
indistinguishable from DSNU. On exponential offsets of mean 60 DN above a 9-DN threshold it
matches the detected offsets' quartiles within ~10 % and their mean within ~2 %.

A hot pixel's extra signal is usually dark *charge* (a local dark current, or charge trapped at a
defect), and dark electrons are Poisson: its temporal variance grows by ``K x offset`` (DN^2, K the
system gain in DN/e-; EMVA 1288 Release 4.0, sec. 4.2). ``shot_noise`` is fitted from the data: on
when the detected pixels' temporal variance in the darks exceeds the others' by more than half of
what Poisson charge would add (summed over the hot pixels), off (a fixed offset, e.g. an ADC or
clamp defect) otherwise. Without a measured K (darks only, no flats) the gain is read from the hot pixels
themselves, their summed variance excess over their summed offsets, when that excess is significant
(:func:`_own_gain`): the same law that gives K from a photon transfer, with dark charge as the signal.

A hot pixel is a local dark current, so its signal grows with the exposure time (EMVA 1288 Release
4.0, sec. 8.5: defect pixels show in the dark image at long exposures). With darks at two exposure
times or more, each detected pixel's signal (temporal mean, profiles removed) is fitted by least
squares as ``offset_i + rate_i t``; when the rates' mean is above 4 standard errors of their noise
the card keeps a log-normal of the rates (``rate_dn_per_s``, its mean, and ``rate_log_sigma``, both
by the moments of the rates, their noise variance taken off) and the offsets become the intercepts at
t = 0 (same moments). Otherwise, and at one exposure time, the offset is the signal in the pooled
dark mean map as above.

Stuck pixels (the same code in every dark and flat frame, ``diagnostics.constant_pixels``) are not hot
ones: they carry no dark signal that grows with time and no temporal noise (``dead_pixels`` models
them). Those reading white, though, may be hot pixels whose offset alone clips at white at this gain
even in the shortest dark: the card is also fitted in the form ``clipped``, with them among the hot
pixels, and the held-out frames choose between the two forms (and ``dead_pixels``).

Profile. ``{type: hot_pixels, hot_fraction, hot_offset, hot_log_sigma}``: the same log-normal, as
its mean ``hot_offset = exp(log_mean + log_sigma^2 / 2) / (white - black)`` on normalised raw and
``hot_log_sigma = log_sigma``; reading it back inverts this exactly (the count is not kept). With
``shot_noise`` also ``hot_electron = K / (white - black)``: the noise stage then draws the offset as
Poisson electrons each frame. With rates also ``hot_rate = rate_dn_per_s / (white - black)`` and
``hot_rate_log_sigma``: the noise stage adds ``rate_i t`` with each frame's exposure time.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, ProfileTerm, quantity


class HotPixels(EffectParams):
    fraction: float = quantity("%", "fraction of the pixels that are hot (dimensionless; shown in %)", scale=100.0)
    log_mean: float = quantity("ln DN", "mean of the natural log of a hot pixel's offset in DN")
    log_sigma: float = quantity("ln DN", "standard deviation of the natural log of a hot pixel's offset in DN")
    count: int | None = quantity("", "number of hot pixels detected in the analysed frames (fits only)", default=None)
    shot_noise: bool | None = quantity("", "the offsets are charge with Poisson shot noise (None: a fixed offset)",
                                       scale=None, default=None)
    gain_dn_per_e: float | None = quantity("DN/e-", "system gain the shot noise is drawn with (with shot_noise)",
                                           default=None)
    rate_dn_per_s: float | None = quantity("DN/s", "mean growth of a hot pixel's signal per second of exposure "
                                           "(None: no exposure dependence)", default=None)
    rate_log_sigma: float | None = quantity("ln", "standard deviation of the natural log of a hot pixel's rate",
                                            default=None)


class HotPixelsCard(EffectCard, name="hot_pixels", params=HotPixels, null_field="fraction", diagnostics=("hot_pixel_tail",),
                    fixed_pattern=True, gaussian=False):
    def variants(self, proposed_by):
        # the pixels reading white in every dark and flat frame are stuck ones or hot ones clipped at white
        # (diagnostics.clipped_constant_pixels): fitted without them and, as the form "clipped", with them
        return [proposed_by[0], (proposed_by[0], "clipped")]

    def fit(self, d, model, ctx):
        clipped = None
        if ctx.form == "clipped":
            clipped = dg.clipped_constant_pixels(d)
            if not clipped.any():  # nothing at white: the same fit as the other form
                return HotPixels(fraction=0.0, log_mean=0.0, log_sigma=0.05, count=0)
        r = d.dark_profile_free_map()
        hot = dg.hot_pixel_mask(d)  # persistent outliers (temporal median), offsets from the mean map
        if not hot.any():  # fewer persistent outliers than the model's (none here): nothing to add
            return HotPixels(fraction=0.0, log_mean=0.0, log_sigma=0.05, count=0)
        vals = r[hot]
        logs = np.log(np.maximum(vals, 1e-3))
        K = float(getattr(model, "K", 0.0) or 0.0)
        if K > 0:
            shot = _shot_noise(d, hot, vals, K)
        else:  # no photon transfer (darks only): the hot pixels' own variance per DN of offset, if significant
            K = _own_gain(d, hot, vals)
            shot = K > 0
        log_mean, log_sigma = float(logs.mean()), float(max(logs.std(), 0.05))
        rate = rate_ls = None
        lines = _offset_and_rate(d, hot)
        if lines is not None:  # a local dark current: intercept + rate x exposure
            (log_mean, log_sigma), (rate, rate_ls) = lines
        count = int(hot.sum())
        if clipped is not None:  # the clipped ones: offsets beyond white, a censored log-normal sample
            # (bound: their level in the shortest darks' mean map, as the others' offsets at one exposure
            # time; with rates the others' are intercepts at t = 0, a rate x 1/50 s below it: a few DN of
            # thousands)
            n_c = int(clipped.sum())
            log_mean, log_sigma = censored_lognormal(log_mean, log_sigma, count, float(np.log(np.median(r[clipped]))), n_c)
            count += n_c
        return HotPixels(fraction=count / hot.size, log_mean=log_mean, log_sigma=log_sigma, count=count,
                         shot_noise=True if shot else None, gain_dn_per_e=K if shot else None,
                         rate_dn_per_s=rate, rate_log_sigma=rate_ls)

    def to_profile(self, p, model):
        mean = float(np.exp(p.log_mean + p.log_sigma ** 2 / 2))
        entry = {"type": "hot_pixels", "hot_fraction": float(p.fraction),
                 "hot_offset": mean / model.full_scale_dn, "hot_log_sigma": float(p.log_sigma)}
        if p.shot_noise and p.gain_dn_per_e:
            entry["hot_electron"] = float(p.gain_dn_per_e) / model.full_scale_dn
        if p.rate_dn_per_s:
            entry["hot_rate"] = float(p.rate_dn_per_s) / model.full_scale_dn
            entry["hot_rate_log_sigma"] = float(p.rate_log_sigma or 0.0)
        return ProfileTerm(effect=entry)

    def from_profile(self, entry, full_scale_dn):
        ls = float(entry.get("hot_log_sigma", 0.0))
        e = entry.get("hot_electron")
        return HotPixels(fraction=float(entry.get("hot_fraction", 0.0)),
                         log_mean=float(np.log(max(entry.get("hot_offset", 0.05) * full_scale_dn, 1e-6)) - ls * ls / 2),
                         log_sigma=ls, shot_noise=True if e else None,
                         gain_dn_per_e=float(e) * full_scale_dn if e else None,
                         rate_dn_per_s=float(entry["hot_rate"]) * full_scale_dn if entry.get("hot_rate") else None,
                         rate_log_sigma=float(entry.get("hot_rate_log_sigma", 0.0)) if entry.get("hot_rate") else None)


def censored_lognormal(m0: float, s0: float, n0: int, log_c: float, n_c: int) -> tuple[float, float]:
    """(log mean, log sigma) of the log-normal by maximum likelihood from ``n0`` observed offsets whose logs
    have mean ``m0`` and SD ``s0`` and ``n_c`` offsets known only to exceed ``exp(log_c)`` (clipped at white):
    the censored-normal likelihood in log space (a Tobit model; J. Tobin, *Econometrica* 26, 1958),
    ``-n0 log s - n0 (s0^2 + (m0 - mu)^2) / (2 s^2) + n_c log Q((log_c - mu) / s)``."""
    if n0 < 2:  # with fewer than 2 observed offsets the scale is not identified: keep it (or 0.3)
        return log_c + 0.3, max(s0, 0.3)
    from scipy.optimize import minimize
    from scipy.special import log_ndtr

    def nll(theta):
        mu, s = theta[0], float(np.exp(theta[1]))
        return -(-n0 * np.log(s) - n0 * (s0 * s0 + (m0 - mu) ** 2) / (2 * s * s) + n_c * log_ndtr((mu - log_c) / s))

    start = np.array([max(m0, log_c), np.log(max(s0, 0.3))])
    res = minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 2000})
    return float(res.x[0]), max(float(np.exp(res.x[1])), 0.05)


def _lognormal_moments(x: np.ndarray, noise_var: float) -> tuple[float, float] | None:
    """(log mean, log sigma) of the log-normal with the mean of ``x`` and its variance less ``noise_var``."""
    mean = float(x.mean())
    if mean <= 0:
        return None
    cv2 = max(float(x.var(ddof=1)) - noise_var, 0.0) / (mean * mean) if x.size > 1 else 0.0
    ls = float(max(np.sqrt(np.log1p(cv2)), 0.05))
    return float(np.log(mean) - ls * ls / 2), ls


def _offset_and_rate(d, hot: np.ndarray):
    """``((offset log mean, log sigma), (rate DN/s, rate log sigma))`` of the hot pixels from darks at two
    exposure times or more (module docstring), or None (one exposure time, no significant rate, or an
    intercept that is not positive)."""
    by_t: dict[float, list] = {}
    for t, f in d.dark_series or []:
        by_t.setdefault(float(t), []).append(f)
    if len(by_t) < 2 or not hot.any():
        return None
    times = np.array(sorted(by_t))
    sig, noise = [], []
    for t in times:
        stacks = [f.astype(np.float64) for f in by_t[t]]
        n = sum(s.shape[0] for s in stacks)
        mean = sum(s.sum(0) for s in stacks) / n
        sig.append(dg.remove_profiles(mean)[hot])
        var = [np.var(s, axis=0, ddof=1)[hot] for s in stacks if s.shape[0] >= 2]
        noise.append(np.mean(var, axis=0) / n if var else np.zeros(int(hot.sum())))
    c = (times - times.mean()) / np.sum((times - times.mean()) ** 2)  # least-squares slope weights
    slope = sum(ci * s for ci, s in zip(c, sig))
    slope_var = sum(ci * ci * v for ci, v in zip(c, noise))
    k = slope.size
    if slope.mean() <= 4.0 * np.sqrt(slope_var.sum()) / k:
        return None
    icpt = sum(s for s in sig) / times.size - slope * times.mean()
    icpt_var = sum((1.0 / times.size - ci * times.mean()) ** 2 * v for ci, v in zip(c, noise))
    off = _lognormal_moments(icpt, float(icpt_var.mean()))
    rate = _lognormal_moments(slope, float(slope_var.mean()))
    if off is None or rate is None:
        return None
    return off, (float(slope.mean()), rate[1])


#: standard errors by which the hot pixels' summed temporal-variance excess must exceed 0 for a gain read
#: from it (:func:`_own_gain`)
OWN_GAIN_Z = 4.0


def _own_gain(d, hot: np.ndarray, offsets: np.ndarray) -> float:
    """The system gain K (DN/e-) the hot pixels' dark charge shows without a photon transfer: Poisson charge
    adds ``K x offset`` to a pixel's temporal variance, so ``K = sum(v_i - v_0) / sum(offset_i)`` (``v_i`` a hot
    pixel's temporal variance in the darks, ``v_0`` the others' median); 0 unless the summed excess is above
    :data:`OWN_GAIN_Z` standard errors (a sample variance of ``m`` degrees of freedom has variance
    ``2 v^2 / m``) and the offsets' sum is positive (a fixed offset: no excess)."""
    if not hot.any() or not d.darks:
        return 0.0
    stacks = [f.astype(np.float64) for f in d.darks if f.shape[0] >= 2]
    if not stacks:
        return 0.0
    dof = sum(f.shape[0] - 1 for f in stacks)
    var = sum(np.var(f, axis=0, ddof=1) * (f.shape[0] - 1) for f in stacks) / dof
    if np.ndim(var) != 2:
        return 0.0
    v0 = float(np.median(var[~hot]))
    excess = float(np.sum(var[hot] - v0))
    se = float(np.sqrt(np.sum(2.0 * var[hot] ** 2 / dof)))
    total = float(np.sum(np.maximum(offsets, 0.0)))
    if total <= 0 or not excess > OWN_GAIN_Z * se:
        return 0.0
    return excess / total


def _shot_noise(d, hot: np.ndarray, offsets: np.ndarray, K: float) -> bool:
    """Whether the hot pixels' temporal variance in the darks exceeds the other pixels' by more than half
    of the Poisson variance ``K x offset`` (DN^2) their offsets would carry as charge (module docstring)."""
    if not hot.any() or not np.isfinite(K) or K <= 0 or not d.darks:
        return False
    var = np.mean([np.var(f.astype(np.float64), axis=0, ddof=1) for f in d.darks if f.shape[0] >= 2], axis=0)
    if np.ndim(var) != 2:
        return False
    excess = float(np.sum(var[hot] - np.median(var[~hot])))
    return excess > 0.5 * K * float(np.sum(np.maximum(offsets, 0.0)))
