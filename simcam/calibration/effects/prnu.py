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

Profile. ``{type: prnu, sigma}``: the same dimensionless sigma.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectParams, GainSigmaCard, quantity


class Prnu(EffectParams):
    sigma: float = quantity("%", "rms relative deviation of the per-pixel gain (dimensionless; shown in %)", scale=100.0,
                            profile="sigma")


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
            s = model.full_scale_dn
            x = (np.sqrt(max(1 + 4 * c * y / s, 1e-9)) - 1) * s / (2 * c)
            sigma /= (x * (1 + 2 * c * x / s)) / y
        cx = model.effects.get("charge_crosstalk")
        if cx is not None and cx.c > 0:  # the sharing filters the pattern too: its variance is f sigma^2
            from .charge_crosstalk import variance_factor

            sigma /= float(np.sqrt(variance_factor(cx.c)))
        return Prnu(sigma=sigma)
