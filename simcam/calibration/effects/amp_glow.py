"""``amp_glow``: amplifier glow, a dark signal growing with the exposure and rising towards the amplifier.

Physics. The output amplifier of a sensor (and any other hot transistor on the chip) emits photons
and heat while it is powered during the integration; the nearby pixels collect the charge. The dark
frame brightens smoothly towards the amplifier: a corner, or an edge where the column or output
amplifiers sit. Like dark current the glow charge accumulates linearly with the integration time and
is Poisson (its shot noise grows with it), but it is a smooth low-frequency field that falls off with
the distance from the amplifier, where the dark current is flat on average with a per-pixel
non-uniformity (DCNU) (J. R. Janesick, *Photon Transfer*, SPIE Press, 2007, on dark current and
amplifier glow; EMVA 1288 Release 4.0, sec. 8: spatial non-uniformity of the dark signal, whose
spatial variance and spectrograms at long exposure show such fields; A. Abdelhamed, *Noise Modelling
for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, dark current and
fixed-pattern noise). The loop models the field as simcam's noise stage draws it
(:class:`simcam.noise.effects.dark.AmpGlow`): pixel (y, x) collects Poisson electrons of mean
``rate_e_per_s * t * exp(-d(y, x) / (scale * L))``, d its distance from ``origin`` (a corner or an
edge) and L the frame's diagonal (corner) or its extent across the edge.

Fit. On the darks at every exposure time: the per-pixel least-squares slope of the dark temporal-mean
images against exposure time (DN/s, hot and defect pixels replaced by their plane's running median:
:func:`simcam.calibration.diagnostics.dark_slope_map`) is fitted, for each origin, by least squares
with the field (one constant per CFA plane takes the flat mean dark current), the scale by a bounded
search in log scale from the best point of the diagnostic's grid; the origin with the largest
explained sum of squares wins. ``rate_e_per_s`` is the field's amplitude over the system gain (the
loop's K; from the darks' variance / mean slopes when the capture gives none). The diagnostic
``glow_field`` is the largest t-value of those fields (:func:`simcam.calibration.diagnostics.glow_field`).

Profile. ``{type: amp_glow, rate, origin, scale, electron}``: the rate in e-/s at the origin, the
origin, the fall-off as a share of L and ``electron = K / (white - black)``; the noise stage draws
Poisson(rate t field) electrons with each frame's exposure time. The field is that of the frame the
loop analysed (the whole frame, the default up to ``--max-pixels``): fitted on a centre crop or a tile
mosaic it is the crop's or the mosaic's. The closed-form marginal leaves it out (it needs the
exposure time), as it does the dark current.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, ProfileTerm, quantity


class AmpGlow(EffectParams):
    rate_e_per_s: float = quantity("e-/s", "glow dark current at the origin (the amplifier), electrons per second")
    origin: str = quantity("", "corner or edge the glow rises to (top_left, top_right, bottom_left, bottom_right, "
                               "top, bottom, left, right)", scale=None)
    scale: float = quantity("", "fall-off length (1/e) as a share of the frame's diagonal (corner) or of its "
                                "extent across the edge")
    gain_dn_per_e: float = quantity("DN/e-", "system gain the electrons are converted with (DN per electron)")
    field_mean: float | None = quantity("", "mean of the field (1 at the origin) over the analysed frame (fits only)",
                                        default=None)
    read_exposure_s: float = quantity("s", "exposure time of the darks the read noise is measured on (s)",
                                      default=0.0)


def _fit_origin(m: np.ndarray, origin: str, scale0: float) -> tuple[float, float, float]:
    """(scale, amplitude in DN/s, explained sum of squares) of the least-squares glow at ``origin``."""
    def explained(log_s):
        tc = dg.glow_template(m.shape, origin, float(np.exp(log_s)))[1]
        proj = float(np.sum(tc * m))
        n2 = float(np.sum(tc * tc))
        return proj, n2

    def cost(log_s):
        proj, n2 = explained(log_s)
        return -(max(proj, 0.0) ** 2) / n2

    lo, hi = np.log(dg.GLOW_SCALES[0] / 2), np.log(dg.GLOW_SCALES[-1] * 2)
    x0 = np.log(scale0)
    r = minimize_scalar(cost, bounds=(max(lo, x0 - 0.5), min(hi, x0 + 0.5)), method="bounded",
                        options={"xatol": 1e-3})
    log_s = float(r.x) if cost(r.x) <= cost(x0) else x0
    proj, n2 = explained(log_s)
    return float(np.exp(log_s)), proj / n2, max(proj, 0.0) ** 2 / n2


class AmpGlowCard(EffectCard, name="amp_glow", params=AmpGlow, diagnostics=("glow_field",), fixed_pattern=True,
                  null_field="rate_e_per_s"):

    def fit(self, d, model, ctx):
        from ..dark_current import series_fit

        m = dg.dark_slope_map(d)
        gain = float(model.K) if np.isfinite(model.K) and model.K > 0 else 0.0
        if gain <= 0:
            r = series_fit(d.dark_series or [], None)
            gain = float(r["gain_dn_per_e"]) if r is not None else 0.0
        if m is None or gain <= 0:
            return AmpGlow(rate_e_per_s=0.0, origin="top_right", scale=0.1, gain_dn_per_e=max(gain, 0.0))
        fits = dg.glow_fits(m)
        best = None
        for o in dg.GLOW_ORIGINS:  # each origin from its best grid point, refined
            f0 = max((f for f in fits if f[0] == o), key=lambda f: f[3])
            s, a, ss = _fit_origin(m, o, f0[1])
            if best is None or ss > best[3]:
                best = (o, s, a, ss)
        o, s, a, _ = best
        t_read = min(float(t) for t, _f in d.dark_series)
        field = dg.glow_template(m.shape, o, s)[0]
        return AmpGlow(rate_e_per_s=float(max(a, 0.0) / gain), origin=o, scale=float(s), gain_dn_per_e=gain,
                       field_mean=float(field.mean()), read_exposure_s=t_read)

    def dark_variance_dn2(self, p):
        mean = 0.0 if p.field_mean is None else float(p.field_mean)
        return float(p.gain_dn_per_e ** 2 * p.rate_e_per_s * mean * p.read_exposure_s)

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": "amp_glow", "rate": float(p.rate_e_per_s), "origin": str(p.origin),
                                   "scale": float(p.scale), "electron": float(p.gain_dn_per_e) / model.full_scale_dn})

    def from_profile(self, entry, full_scale_dn):
        return AmpGlow(rate_e_per_s=float(entry["rate"]), origin=str(entry.get("origin", "top_right")),
                       scale=float(entry.get("scale", 0.1)), gain_dn_per_e=float(entry["electron"]) * full_scale_dn)
