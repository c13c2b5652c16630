"""``dsnu``: dark-signal non-uniformity, a fixed offset per pixel.

Physics. Pixels differ in their dark signal (dark-current and offset non-uniformity): an offset
``~ N(0, sigma^2)`` per pixel, drawn once per sensor and the same in every frame (EMVA 1288 Release
4.0, sec. 4: spatial nonuniformity, DSNU, and sec. 8 for its measurement; A. Abdelhamed, *Noise
Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, fixed-pattern
noise). An offset after the response, it adds sigma^2 to a pixel's variance about the plane mean.

Fit. ``dsnu_excess``: sigma^2 is the variance within 5 robust sigmas (hot pixels left out,
:func:`~simcam.calibration.diagnostics.clipped_variance`) of the dark temporal-mean map with its
per-plane median and its row and column profiles removed, minus the temporal variance
left in that map, ``var_left / n`` (EMVA 1288's correction for the residual temporal noise of averaged
frames). ``var_left`` is the temporal variance of the dark frames with the same profiles removed from
each frame's deviation: temporal noise shared along a row or a column (row noise, a per-frame plane
offset) leaves the mean map with its profiles, so subtracting the whole temporal variance would take
it away twice (with row noise of 2.7 DN rms beside 1.5 DN of DSNU, sigma came out 22 % low).
Proposed by its diagnostic (``dsnu_excess`` = that clipped variance over ``var_left / n``: about 1
without DSNU whatever row or column noise the darks carry), the fit
is the diagnostic's excess over the current model's parametric bootstrap instead,
``sigma^2 = (value - sim_mean) var_left / n``: the simulated captures carry the temporal noise, the
model's other fixed patterns and what is left of the spread estimator's bias on coarsely quantised darks.
(A mean map of a few integer codes sits on a lattice of 1/n DN. The MAD the statistic used before
stuck to one lattice step there: on an independent simulator's ISO-100 darks, 0.33 DN of DSNU beside
0.9 DN of read noise, adding 0.19 DN of DSNU did not move the simulated statistic at all.)

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
        n = d.dark_map()[2]
        if ctx.diagnostic == "dsnu_excess" and np.isfinite(ctx.value) and np.isfinite(ctx.sim_mean):
            # the excess over the current model's bootstrap (module docstring): the robust spread's bias on
            # coarse codes, the temporal noise and the model's own fixed patterns are in the simulated mean
            s2 = (float(ctx.value) - float(ctx.sim_mean)) * d.profile_free_dark_variance() / n
        else:
            s2 = dg.clipped_variance(d.dark_profile_free_map()) - d.profile_free_dark_variance() / n
        return Dsnu(sigma_dn=float(np.sqrt(max(s2, 0.0))))
