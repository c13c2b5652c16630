"""``empirical_response``: a response that curves by a different amount in every pixel, measured on
the flats, for a fixed pattern that grows faster than the signal.

Physics. ``prnu`` is a gain: its relative spread is the same at every signal level (EMVA 1288
Release 4.0, sec. 8.2). ``nonlinearity`` bends the response of every pixel alike (sec. 6). Where the
floating-diffusion capacitance or the source follower differs from pixel to pixel, each pixel bends by
its own amount, ``y_p = x + c_p x^2 / s`` (DN above black, ``s = white - black``): the mean of ``c_p``
is the common non-linearity, and its spread adds ``sd(c)^2 x^2 / s^2`` to the flats' relative
fixed-pattern variance, which then grows with the signal (A. Abdelhamed, *Noise Modelling for
Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2: fixed-pattern noise and the
camera's response). The vocabulary has no per-pixel response, so the loop adds this *empirical*
component and the report says it is not in the vocabulary, with its family: pixel, fixed,
multiplicative (grows with the signal squared), not exposure-dependent.

Fit. Proposed by ``flat_spread_growth`` (the relative fixed-pattern variance of the brightest flat
minus that of a dimmer one). From the two flats' even/odd-frame covariances
(:func:`simcam.calibration.diagnostics.prnu_by_level`, jackknife standard errors; a modelled
nonlinearity's elasticity divided out as ``prnu`` does), ``v(L) = sigma^2 + sd(c)^2 L^2 / s^2``
through the two levels gives ``sd(c)``; where the rise is within ``prnu.LEVEL_Z`` standard errors the
fit is null and says so. The mean ``c`` is the photon-transfer curvature of ``nonlinearity``'s fit
(zero where ``nonlinearity`` is already in the model: the component then holds the spread only). The
*law* of ``c_p`` is measured pixel by pixel: per CFA plane, the two flats' relative deviations from
their plane means differ by ``(c_p - mean c) (L_hi - L_lo) / s`` (a gain cancels, the darks' mean map is
subtracted first); the deviations, 8 robust sigma trimmed, are scaled to the covariance estimate's
``sd(c)`` (temporal noise inflates their spread; it does not move their shape much) and kept as
``QUANTILES`` quantiles, so a skewed law (every pixel compressing, some more) is kept as measured.

Profile. ``{type: empirical_response, quantiles}``: the per-pixel ``strength = -c_p`` of the noise stage's
``y = x - strength x^2`` on normalised raw, at probabilities linspace(0, 1, n), drawn once per sensor
(:class:`simcam.noise.effects.empirical.EmpiricalResponse`).
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, Fit, ProfileTerm, quantity

#: quantiles of the per-pixel curvature's law kept in the profile
QUANTILES = 33
#: largest |strength| of the noise stage's response (monotonic below x = 1.1)
STRENGTH_LIMIT = 0.45


class EmpiricalResponse(EffectParams):
    c_mean: float = quantity("% at white", "mean per-pixel curvature c of y = x + c x^2 / (white - black) "
                             "(the common non-linearity; 0 where nonlinearity holds it)", scale=100.0)
    c_sd: float = quantity("% at white", "spread (sd) of the per-pixel curvature", scale=100.0)
    quantiles: list | None = quantity("% at white", "the measured law of c_p - c_mean: quantiles at probabilities "
                                      "linspace(0, 1, n)", scale=100.0, default=None)
    growth_z: float | None = quantity("", "standard errors by which the brighter flat's relative fixed-pattern "
                                      "variance exceeds the dimmer's", scale=None, default=None)


def curvature_deviations(d, s: float) -> np.ndarray | None:
    """Per pixel, ``c_p - mean c`` measured from the two flats of :func:`diagnostics.flat_level_pair`:
    ``(r_hi - r_lo) s / (L_hi - L_lo)`` with ``r`` a pixel's relative deviation from its plane's mean
    (above the darks' mean map or the black level) and ``L`` the planes' signals (DN). None without such
    a pair of flats or a dark reference."""
    dm = d.dark_map()
    if dm is None and d.black_dn is None:
        return None
    black = None if dm is not None else np.asarray(d.black_dn, dtype=np.float64).reshape(2, 2)

    def above(mean_map, dy, dx):  # one CFA plane of a flat's mean map, above the dark reference
        ref = dm[0][dy::2, dx::2] if dm is not None else black[dy, dx]
        return mean_map[dy::2, dx::2] - ref

    means = [f.astype(np.float64).mean(0) for f in d.flats if f.shape[0] >= 2]
    levels = [float(np.mean([above(m, dy, dx).mean() for dy, dx in dg.PLANE_OFFSETS])) for m in means]
    # flat_level_pair reads the level (first item) of each row; the second carries the flat's index
    pair = dg.flat_level_pair(sorted((lv, i, 0.0) for i, lv in enumerate(levels)))
    if pair is None:
        return None
    lo, hi = means[pair[0][1]], means[pair[1][1]]
    out = []
    for dy, dx in dg.PLANE_OFFSETS:
        a, c = above(hi, dy, dx), above(lo, dy, dx)
        la, lc = float(a.mean()), float(c.mean())
        if min(la, lc) <= 0 or la <= lc:
            return None
        out.append(((a / la - c / lc) * (s / (la - lc))).ravel())
    return np.concatenate(out)


def _law_moments(q: np.ndarray) -> tuple[float, float]:
    """Mean and sd of the law whose quantile function is piecewise linear through ``q`` at linspace(0, 1, n)."""
    if q.size < 2:
        return float(q[0]) if q.size else 0.0, 0.0
    lo, hi = q[:-1], q[1:]
    mean = float(np.mean((lo + hi) / 2))
    second = float(np.mean((lo * lo + lo * hi + hi * hi) / 3))  # exact on each linear piece
    return mean, float(np.sqrt(max(second - mean * mean, 0.0)))


def measured_law(dev: np.ndarray, sd: float, n: int = QUANTILES) -> list[float]:
    """``n`` quantiles of the deviations ``dev`` (8 robust sigma trimmed) at probabilities linspace(0, 1, n),
    shifted and scaled so that the law the noise stage draws from them (piecewise linear between the
    quantiles, :func:`simcam.noise.effects.empirical.draw_quantiles`) has mean 0 and spread ``sd``; the two
    end points hold their segments' sample means (the sample's extremes would stretch the tails)."""
    med = float(np.median(dev))
    mad = 1.4826 * float(np.median(np.abs(dev - med)))
    keep = dev[np.abs(dev - med) <= 8.0 * mad] if mad > 0 else dev
    q = np.quantile(keep, np.linspace(0.0, 1.0, n))
    # the end points: not the sample's extremes (whose linear segments would put too much mass far out) but the
    # values that give each end segment the mean of the sample's values in it
    q[0] = 2.0 * float(keep[keep <= q[1]].mean()) - q[1]
    q[-1] = 2.0 * float(keep[keep >= q[-2]].mean()) - q[-2]
    mean, spread = _law_moments(q)
    q = (q - mean) * (sd / spread if spread > 0 else 0.0)
    return [float(v) for v in q]


class EmpiricalResponseCard(EffectCard, name="empirical_response", params=EmpiricalResponse,
                            diagnostics=("flat_spread_growth",), fixed_pattern=True, marginal_rank=51,
                            null_field="c_sd", refit_on_change=True,
                            family="pixel, fixed, multiplicative (grows with the signal squared), "
                                   "not exposure-dependent"):

    def fit(self, d, model, ctx):
        from .nonlinearity import NonlinearityCard
        from .prnu import LEVEL_Z, spread_growth

        s = model.full_scale_dn
        nl = model.effects.get("nonlinearity")
        growth = spread_growth(d, nl.c if nl is not None else 0.0, s)
        if growth is None:
            return EmpiricalResponse(c_mean=0.0, c_sd=0.0)
        z = growth.z
        if not z > LEVEL_Z:
            return EmpiricalResponse(c_mean=0.0, c_sd=0.0, growth_z=z)
        c_sd = float(np.sqrt(growth.slope)) * s
        dev = curvature_deviations(d, s)
        law = measured_law(dev, c_sd) if dev is not None and dev.size >= 16 else []
        if nl is not None:  # the common bend is nonlinearity's
            return EmpiricalResponse(c_mean=0.0, c_sd=c_sd, quantiles=law, growth_z=float(z))
        common = NonlinearityCard().fit(d, model, ctx)
        return Fit(EmpiricalResponse(c_mean=float(common.params.c), c_sd=c_sd, quantiles=law, growth_z=float(z)),
                   K=common.K)

    def null_reason(self, p):
        if p.growth_z is not None and not p.c_sd:
            return (f"the flats' relative fixed pattern does not grow with the signal beyond its sampling noise "
                    f"(z = {p.growth_z:.3g})")
        return None

    def _strengths(self, p) -> list[float]:
        law = list(p.quantiles or []) or [-p.c_sd * np.sqrt(3.0), p.c_sd * np.sqrt(3.0)]  # no measured law: uniform
        return sorted(float(np.clip(-(p.c_mean + q), -STRENGTH_LIMIT, STRENGTH_LIMIT)) for q in law)

    def marginal(self, p, v, lin, model):
        s = model.full_scale_dn
        return v * (1 + 2 * p.c_mean * lin / s) ** 2 + (p.c_sd * lin * lin / s) ** 2

    def linear_signal(self, p, y, model):
        """The inverse of the mean response (``c_mean``) in DN."""
        from .nonlinearity import response_inverse_dn

        return response_inverse_dn(p.c_mean, y, model.full_scale_dn)

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": self.name, "quantiles": self._strengths(p)})

    def from_profile(self, entry, full_scale_dn):
        if entry.get("quantiles") is not None:
            c = -np.asarray(entry["quantiles"], dtype=np.float64) * float(entry.get("scale", 1.0))
        else:  # a measured map
            from ...noise.maps import load_map

            c = -np.asarray(load_map(entry["map"]), dtype=np.float64).ravel() * float(entry.get("scale", 1.0))
            c = np.quantile(c, np.linspace(0.0, 1.0, QUANTILES))
        c = np.sort(c)
        mean, sd = _law_moments(c)
        return EmpiricalResponse(c_mean=mean, c_sd=sd, quantiles=[float(v - mean) for v in c])

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        q = np.asarray(p.quantiles or [], float)
        law = (f"; quantiles = {q.size} of c_p - c_mean from {100 * q.min():.3g} to {100 * q.max():.3g} % at white"
               if q.size else "")
        return (f"c_mean = {100 * p.c_mean:.3g} % at white; c_sd = {100 * p.c_sd:.3g} % at white" + law
                + ("" if p.growth_z is None else f"; growth_z = {p.growth_z:.3g}"))
