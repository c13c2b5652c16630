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

Profile. ``{type: hot_pixels, hot_fraction, hot_offset, hot_log_sigma}``: the same log-normal, as
its mean ``hot_offset = exp(log_mean + log_sigma^2 / 2) / (white - black)`` on normalised raw and
``hot_log_sigma = log_sigma``; reading it back inverts this exactly (the count is not kept).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, ProfileTerm, quantity


@dataclass(frozen=True)
class HotPixels(EffectParams):
    fraction: float = quantity("%", "fraction of the pixels that are hot (dimensionless; shown in %)", scale=100.0)
    log_mean: float = quantity("ln DN", "mean of the natural log of a hot pixel's offset in DN")
    log_sigma: float = quantity("ln DN", "standard deviation of the natural log of a hot pixel's offset in DN")
    count: int | None = quantity("", "number of hot pixels detected in the analysed frames (fits only)", default=None)


class HotPixelsCard(EffectCard):
    name = "hot_pixels"
    params = HotPixels
    null_field = "fraction"
    diagnostics = ("hot_pixel_tail",)
    fixed_pattern = True
    gaussian = False

    def fit(self, d, model, ctx):
        m, _vt, _n = d.dark_map()
        r = dg.remove_profiles(m)
        hot = dg.hot_pixel_mask(d)  # persistent outliers (temporal median), offsets from the mean map
        vals = r[hot]
        logs = np.log(np.maximum(vals, 1e-3))
        return HotPixels(fraction=float(hot.mean()), log_mean=float(logs.mean()),
                         log_sigma=float(max(logs.std(), 0.05)), count=int(hot.sum()))

    def to_profile(self, p, model):
        mean = float(np.exp(p.log_mean + p.log_sigma ** 2 / 2))
        return ProfileTerm(effect={"type": "hot_pixels", "hot_fraction": float(p.fraction),
                                   "hot_offset": mean / model.full_scale_dn, "hot_log_sigma": float(p.log_sigma)})

    def from_profile(self, entry, full_scale_dn):
        ls = float(entry.get("hot_log_sigma", 0.0))
        return HotPixels(fraction=float(entry.get("hot_fraction", 0.0)),
                         log_mean=float(np.log(max(entry.get("hot_offset", 0.05) * full_scale_dn, 1e-6)) - ls * ls / 2),
                         log_sigma=ls)
