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
clamp defect) otherwise; it needs a measured K.

Profile. ``{type: hot_pixels, hot_fraction, hot_offset, hot_log_sigma}``: the same log-normal, as
its mean ``hot_offset = exp(log_mean + log_sigma^2 / 2) / (white - black)`` on normalised raw and
``hot_log_sigma = log_sigma``; reading it back inverts this exactly (the count is not kept). With
``shot_noise`` also ``hot_electron = K / (white - black)``: the noise stage then draws the offset as
Poisson electrons each frame.
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


class HotPixelsCard(EffectCard, name="hot_pixels", params=HotPixels, null_field="fraction", diagnostics=("hot_pixel_tail",),
                    fixed_pattern=True, gaussian=False):
    def fit(self, d, model, ctx):
        m, _vt, _n = d.dark_map()
        r = dg.remove_profiles(m)
        hot = dg.hot_pixel_mask(d)  # persistent outliers (temporal median), offsets from the mean map
        if not hot.any():  # fewer persistent outliers than the model's (none here): nothing to add
            return HotPixels(fraction=0.0, log_mean=0.0, log_sigma=0.05, count=0)
        vals = r[hot]
        logs = np.log(np.maximum(vals, 1e-3))
        K = float(getattr(model, "K", 0.0) or 0.0)
        shot = _shot_noise(d, hot, vals, K)
        return HotPixels(fraction=float(hot.mean()), log_mean=float(logs.mean()),
                         log_sigma=float(max(logs.std(), 0.05)), count=int(hot.sum()),
                         shot_noise=True if shot else None, gain_dn_per_e=K if shot else None)

    def to_profile(self, p, model):
        mean = float(np.exp(p.log_mean + p.log_sigma ** 2 / 2))
        entry = {"type": "hot_pixels", "hot_fraction": float(p.fraction),
                 "hot_offset": mean / model.full_scale_dn, "hot_log_sigma": float(p.log_sigma)}
        if p.shot_noise and p.gain_dn_per_e:
            entry["hot_electron"] = float(p.gain_dn_per_e) / model.full_scale_dn
        return ProfileTerm(effect=entry)

    def from_profile(self, entry, full_scale_dn):
        ls = float(entry.get("hot_log_sigma", 0.0))
        e = entry.get("hot_electron")
        return HotPixels(fraction=float(entry.get("hot_fraction", 0.0)),
                         log_mean=float(np.log(max(entry.get("hot_offset", 0.05) * full_scale_dn, 1e-6)) - ls * ls / 2),
                         log_sigma=ls, shot_noise=True if e else None,
                         gain_dn_per_e=float(e) * full_scale_dn if e else None)


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
