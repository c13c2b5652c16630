"""``dark_current``: thermally generated electrons that accumulate during the exposure.

Physics. Thermal generation in the photodiode (and at its surface) adds electrons at a rate that
depends on the temperature, not on the light: the dark signal grows linearly with the exposure time
t, ``mu_dark(t) = mu_dark(0) + K mu_I t`` (DN), and, the electrons being Poisson, so does the dark
temporal variance, ``sigma_dark^2(t) = sigma_dark^2(0) + K^2 mu_I t`` (EMVA 1288 Release 4.0,
sec. 4.2 and 8.4: the dark current from the dark signal and the dark variance against exposure
time; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University,
2020, ch. 2, dark current). The rate differs from pixel to pixel (dark-current non-uniformity,
DCNU); the loop models it as a log-normal of mean ``rate_e_per_s`` and log-spread ``log_sigma``,
the law simcam's noise stage draws (:class:`simcam.noise.effects.dark.DarkCurrent`). Only darks at
two exposure times or more separate it from the black level: at one exposure time a dark current
is an offset (``black_level_offset``) and its non-uniformity a DSNU. Being Poisson charge, it raises
the dark temporal variance by K times the dark level's rise (``dark_variance_slope``, EMVA 1288's
variance method, beside ``dark_signal_slope``): a dark level that rises between exposures without
that growth (a black level drifting over the capture) scores worse with this effect than without it,
and the fit does not take it for dark current: where the variance's rise falls short of K times the
level's by more than 3 standard errors and by more than half, the rate is the variance method's (the
Poisson part alone) and what is left of the level's rise is reported (``non_poisson_dn_per_s``), not
simulated.

Fit. On the darks at every exposure time (the loop's dark diagnostics use the shortest one only,
as EMVA 1288 measures the temporal dark noise there): least-squares slopes of the mean dark level
and of the temporal variance against exposure time (:func:`simcam.calibration.dark_current.series_fit`);
``rate_e_per_s`` = mean slope / K (K from the variance slope / mean slope when the capture gives
none), the mean slope over the pixels' least-squares slopes less those beyond 10 robust sigma above
the median (hot pixels whose charge also grows with the exposure), ``log_sigma`` from the robust
spread of the per-pixel slopes (row and column profiles removed), the log-normal whose robust spread,
with the temporal noise the slopes carry, is the measured one
(:func:`simcam.calibration.dark_current.lognormal_log_sigma`). ``read_exposure_s`` is the shortest exposure time:
the read noise is the dark variance there less the dark current's shot noise.
With an amplifier glow in the model (``amp_glow``, a smooth dark signal that also grows with the
exposure) its expected charge, ``K rate_glow t field``, is taken off the darks before the fit, and the
dark current is fitted again whenever the glow is added.

Profile. ``{type: dark_current, rate, dcnu_log_sigma, electron}``: rate in e-/s, the log-normal
spread, and ``electron = K / (white - black)``; the noise stage draws Poisson(rate_i t) electrons
with each frame's exposure time t (the loop's bootstrap passes every sequence's ``exposure_s``).
The closed-form marginal leaves it out (it needs the exposure time): a small term at the short
exposures of flats and scenes.
"""

from __future__ import annotations

import numpy as np

from ..dark_current import series_fit
from .card import DeclaredProfileCard, EffectParams, quantity


class DarkCurrent(EffectParams):
    rate_e_per_s: float = quantity("e-/s", "mean dark current over the pixels, electrons per second", profile="rate")
    log_sigma: float = quantity("ln", "dark-current non-uniformity: standard deviation of the log of a pixel's rate",
                                profile="dcnu_log_sigma", profile_default=0.0)
    gain_dn_per_e: float = quantity("DN/e-", "system gain the electrons are converted with (DN per electron)",
                                    profile="electron", per_full_scale=True)
    read_exposure_s: float = quantity("s", "exposure time of the darks the read noise is measured on (s)",
                                      default=0.0)
    non_poisson_dn_per_s: float = quantity("DN/s", "rise of the dark level with the exposure time that the dark "
                                           "variance does not follow (not Poisson charge: not in the rate, not "
                                           "simulated)", default=0.0)


class DarkCurrentCard(DeclaredProfileCard, name="dark_current", params=DarkCurrent,
                      diagnostics=("dark_signal_slope", "dark_variance_slope"),
                      null_field="rate_e_per_s", refit_after=("amp_glow",)):

    def fit(self, d, model, ctx):
        r = series_fit(_without_glow(d.dark_series or [], model), model.K)
        if r is None or r["e_per_s"] <= 0 or r["gain_dn_per_e"] <= 0:
            return DarkCurrent(rate_e_per_s=0.0, log_sigma=0.0, gain_dn_per_e=float(max(model.K, 0.0)),
                               non_poisson_dn_per_s=float(r["non_poisson_dn_per_s"]) if r else 0.0)
        return DarkCurrent(rate_e_per_s=float(r["e_per_s"]), log_sigma=float(r["log_sigma"]),
                           gain_dn_per_e=float(r["gain_dn_per_e"]), read_exposure_s=float(r["exposure_s"][0]),
                           non_poisson_dn_per_s=float(r["non_poisson_dn_per_s"]))

    def null_reason(self, p):
        if p.non_poisson_dn_per_s > 0:
            return (f"the dark level rises by {p.non_poisson_dn_per_s:.3g} DN/s with the exposure time and the "
                    "dark temporal variance does not rise with it (not Poisson charge)")
        return None

    def dark_variance_dn2(self, p):
        return float(p.gain_dn_per_e ** 2 * p.rate_e_per_s * p.read_exposure_s)


def _without_glow(series: list, model) -> list:
    """The dark series less the model's amplifier glow's expected charge (DN), or as it is without one."""
    g = model.effects.get("amp_glow")
    if g is None or not series or g.rate_e_per_s <= 0:
        return series
    from ..diagnostics import glow_template

    field = glow_template(series[0][1].shape[1:], g.origin, g.scale)[0] * (g.gain_dn_per_e * g.rate_e_per_s)
    return [(t, f.astype(np.float64) - field * float(t)) for t, f in series]
