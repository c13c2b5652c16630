"""``dsnu``: dark-signal non-uniformity, a fixed offset per pixel.

Physics. Pixels differ in their dark signal (dark-current and offset non-uniformity): an offset
``~ N(0, sigma^2)`` per pixel, drawn once per sensor and the same in every frame (EMVA 1288 Release
4.0, sec. 4: spatial nonuniformity, DSNU, and sec. 8 for its measurement; A. Abdelhamed, *Noise
Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, fixed-pattern
noise). An offset after the response, it adds sigma^2 to a pixel's variance about the plane mean.

Fit. ``dsnu_excess``: sigma^2 is the robust variance (1.4826 MAD, squared) of the dark temporal-mean
map with its per-plane median and its row and column profiles removed, minus the temporal variance
left in the mean, ``var / n`` (EMVA 1288's correction for the residual temporal noise of averaged
frames).

Profile. ``{type: dsnu, sigma}`` with sigma on normalised raw, ``sigma_dn / (white - black)``.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectParams, OffsetSigmaCard, quantity


class Dsnu(EffectParams):
    sigma_dn: float = quantity("DN", "rms of the per-pixel offset (DN)", profile="sigma", per_full_scale=True)


class DsnuCard(OffsetSigmaCard, name="dsnu", params=Dsnu, diagnostics=("dsnu_excess",), fixed_pattern=True,
               marginal_rank=60):

    def fit(self, d, model, ctx):
        m, vt, n = d.dark_map()
        s2 = dg.robust_sigma(dg.remove_profiles(m)) ** 2 - vt / n
        return Dsnu(sigma_dn=float(np.sqrt(max(s2, 0.0))))
