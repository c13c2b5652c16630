"""``spatial_correlation``: crosstalk of the read noise between same-colour neighbours.

Physics. Shared readout circuitry and electrical crosstalk couple the read noise of neighbouring
pixels of one CFA plane: the noise stage filters it inside each plane with the separable kernel
[a, 1, a] x [a, 1, a], renormalised to keep its variance, so the in-plane lag-1 correlation is
2a / (1 + 2a^2) and lag-2 a^2 / (1 + 2a^2), and different-colour neighbours stay independent
(EMVA 1288 Release 4.0, sec. 8: spatially non-white temporal noise; A. Abdelhamed, *Noise Modelling
for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, crosstalk). Shot noise
stays white. The variance, hence the closed-form marginal, is unchanged.

Fit. Indirect inference: the a whose simulated in-plane lag-1 correlation of dark residuals
(``lag1_corr``; diluted by quantisation noise, hence no closed form) matches the data, on a grid
over [0, 0.5]; needs darks.

Profile. ``{type: spatial_correlation, coefficient}``: the loop's ``a`` (same kernel).
"""

from __future__ import annotations

import numpy as np

from .card import DeclaredProfileCard, EffectParams, quantity
from .indirect import indirect_fit

#: grid of the indirect fit
GRID = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)


class SpatialCorrelation(EffectParams):
    a: float = quantity("", "coupling of the in-plane [a, 1, a] kernel of the read noise (dimensionless, 0 to 0.5)",
                        profile="coefficient")


class SpatialCorrelationCard(DeclaredProfileCard, name="spatial_correlation", params=SpatialCorrelation, null_field="a",
                             diagnostics=("lag1_corr", "lag2_corr"), needs_darks=True):

    def fit(self, d, model, ctx):
        a = indirect_fit(d, model, self.name, lambda g: SpatialCorrelation(a=float(g)), list(GRID), "lag1_corr",
                         ctx.dark_specs, ctx.seed, ctx.simulate)
        return SpatialCorrelation(a=float(np.clip(a, 0.0, 0.5)))
