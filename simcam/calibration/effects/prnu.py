"""``prnu``: photo-response non-uniformity, a fixed per-pixel gain on the expected signal.

Physics. Pixels differ in sensitivity (photodiode area, microlens, quantum efficiency): pixel p
collects ``mu_e (1 + n_p)`` photo-electrons on average, ``n_p ~ N(0, sigma^2)`` drawn once per
sensor, so the spatial spread of a flat grows in proportion to its signal (EMVA 1288 Release 4.0,
sec. 4, spatial nonuniformity: PRNU; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
dissertation, York University, 2020, ch. 2, fixed-pattern noise). About the plane mean it adds
``(sigma x)^2`` to a pixel's variance, x the linear signal above black (DN).

Fit. ``prnu_excess``: per CFA plane, the covariance of the even- and odd-frame mean maps of the
flat minus the same of the darks, over the signal squared (only the fixed pattern survives in the
covariance, offsets common to dark and flat cancel). With a modelled nonlinearity y(x) the
measured relative spread is the linear one times the elasticity x y'(x) / y, divided out. With a
modelled charge crosstalk (``charge_crosstalk``: photo-electrons shared with the adjacent pixels
before read-out) the pattern is shared with the charge, ``(1 - 4c) n_p + c (4 adjacent n)``, so the
measured variance is ``f sigma^2`` with ``f = (1 - 4c)^2 + 4c^2``, divided out too. The estimate
depends on the rest of the model and is refitted whenever another effect is added.

Check. A gain gives the same relative spread at every signal level. Where the capture has flats at
two levels (the dimmer at 10-80 % of the brighter), the relative fixed-pattern variance is measured on
each (:func:`simcam.calibration.diagnostics.prnu_by_level`, standard errors by a jackknife over bands
of rows, a modelled nonlinearity's elasticity divided out at each level). Where the brighter flat's
exceeds the dimmer's by more than ``LEVEL_Z`` standard errors, part of the pattern grows with the
signal (a per-pixel non-linearity: each pixel's response curving by its own amount, ``e (1 - c_p e / FW)``,
whose relative deviation grows as the signal): the two levels are split
into ``v(L) = sigma^2 + k L^2``; where the level-independent part is within 3 standard errors of 0 the
fit is null and the report says why (``spread_growth``: the ratio of the relative spreads of the two
flats); otherwise the brightest flat's estimate is kept (the intercept instead, tried on the
independent simulator's PRNU beside a per-pixel non-linearity, left part of the pattern to a global
``nonlinearity``, which the loop then added). The real Basler CCD set of EMVA 1288 measurements gives
0.27-0.28 % at every level from 1,000 to 3,900 DN.

Profile. ``{type: prnu, sigma}``: the same dimensionless sigma.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import diagnostics as dg
from .card import EffectParams, GainSigmaCard, quantity

#: standard errors by which the relative variance of the brighter flat must exceed the dimmer's for part of
#: the pattern to be taken as growing with the signal
LEVEL_Z = 4.0


class Prnu(EffectParams):
    sigma: float = quantity("%", "rms relative deviation of the per-pixel gain (dimensionless; shown in %)", scale=100.0,
                            profile="sigma")
    spread_growth: float | None = quantity("x", "relative spread of the brightest flat over that of the dimmest at "
                                           "10-80 % of its signal, where it grows significantly (else not given)",
                                           default=None)


def _elasticity(c: float, y: float, s: float) -> float:
    """x y'(x) / y of the response y = x (1 + c x / s) at the output level y (DN above black)."""
    x = (np.sqrt(max(1 + 4 * c * y / s, 1e-9)) - 1) * s / (2 * c)
    return (x * (1 + 2 * c * x / s)) / y


class LevelGrowth(NamedTuple):
    """:func:`spread_growth`'s result: the flats' relative fixed-pattern variance at two levels, fitted as
    ``v(L) = intercept + slope L^2`` (L in DN above the darks)."""

    ratio: float  # relative spread of the brighter flat over the dimmer's
    z: float  # standard errors by which the brighter flat's relative variance exceeds the dimmer's
    intercept: float  # the level-independent relative variance (a gain's)
    intercept_se: float
    slope: float  # the part growing as L^2 (a per-pixel response curvature's: sd(c)^2 / s^2)


def spread_growth(d, c: float, s: float) -> LevelGrowth | None:
    """The relative fixed-pattern variances of the brightest flat and of the dimmest at 10-80 % of its
    signal, a nonlinearity ``c`` (full scale ``s``) divided out, through ``v(L) = intercept + slope L^2``
    (:class:`LevelGrowth`); None without such a pair of flats."""
    pair = dg.flat_level_pair(dg.prnu_by_level(d))
    if pair is None:
        return None
    lo, hi = pair
    e = [(_elasticity(c, r[0], s) if c else 1.0) ** 2 for r in (lo, hi)]
    vlo, vhi = lo[1] / e[0], hi[1] / e[1]
    slo, shi = lo[2] / e[0], hi[2] / e[1]
    z = (vhi - vlo) / max(float(np.hypot(slo, shi)), 1e-300)
    a2, b2 = hi[0] ** 2, lo[0] ** 2  # v(L) = sigma^2 + k L^2 through the two points
    icpt = (vlo * a2 - vhi * b2) / (a2 - b2)
    icpt_se = float(np.hypot(a2 * slo, b2 * shi)) / (a2 - b2)
    ratio = float(np.sqrt(max(vhi, 0.0) / vlo)) if vlo > 0 else float("inf")
    return LevelGrowth(ratio, float(z), float(icpt), icpt_se, float((vhi - vlo) / (a2 - b2)))


class PrnuCard(GainSigmaCard, name="prnu", params=Prnu, diagnostics=("prnu_excess",), fixed_pattern=True, marginal_rank=40,
               refit_on_change=True):

    def fit(self, d, model, ctx):
        v = dg.prnu_excess(d)
        sigma = float(np.sqrt(max(v, 0.0)))
        nl = model.effects.get("nonlinearity")
        c = nl.c if nl is not None else 0.0
        if c:
            fm, dm = d.flat_map(), d.dark_map()
            y = float(fm[0].mean() - (dm[0].mean() if dm is not None else np.mean(model.black_dn)))
            sigma /= _elasticity(c, y, model.full_scale_dn)
        growth, ratio = spread_growth(d, c, model.full_scale_dn), None
        if growth is not None and growth.z > LEVEL_Z:
            # part of the pattern grows with the signal: a gain only where a level-independent part is left
            if not growth.intercept > 3 * growth.intercept_se:
                sigma = 0.0
            ratio = min(growth.ratio, 1e6)
        cx = model.effects.get("charge_crosstalk")
        if cx is not None and cx.c > 0:  # the sharing filters the pattern too: its variance is f sigma^2
            from .charge_crosstalk import variance_factor

            sigma /= float(np.sqrt(variance_factor(cx.c)))
        return Prnu(sigma=sigma, spread_growth=ratio)

    def null_reason(self, p):
        if p.spread_growth is not None:
            return (f"the flats' relative fixed pattern grows with the signal ({p.spread_growth:.3g}x from the dimmer "
                    "flat to the brighter): not a gain")
        return None
