"""``channel_gain``: a gain per CFA site after photon counting (per-channel analogue gain).

Physics. Each 2x2 site's signal chain (column amplifier, analogue gain) converts electrons to DN
with its own gain ``K g_c``: both the mean and the shot-noise variance of site c scale, so the
photon-transfer slope differs between the planes (EMVA 1288 Release 4.0, sec. 2, linear signal
model: system gain K; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation,
York University, 2020, eq. 3.6, the Poisson-Gaussian noise level function beta1 x + beta2 with one
beta1 per channel). It enters the closed-form marginal through the shot-noise term ``K g_c x`` of
the base.

Fit. Per-plane photon-transfer slopes k_c (``plane_gain_spread``), each divided by the factor the
model's other effects put on the shot term (``FitContext.shot_factor``; charge
sharing lowers it): ``g = k / mean(k)``, and the system gain K is re-estimated as ``mean(k)``.

Profile. A gain after photon counting changes the variance-to-mean ratio, so it is written as the
base's per-site ``beta1 = K g_c / (white - black)``, not as the noise stage's ``channel_gain``
effect (which scales the expected signal, a quantum-efficiency difference); reading a profile,
a per-site ``beta1`` spread becomes ``channel_gain`` again, and so does a noise-stage
``channel_gain`` entry (its ``gain``).
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import DeclaredProfileCard, EffectParams, Fit, ProfileTerm, quantity


class ChannelGain(EffectParams):
    gains: list = quantity("×", "relative gain of each 2x2 site (00, 01, 10, 11), dimensionless, mean 1 when fitted",
                           profile="gain")


class ChannelGainCard(DeclaredProfileCard, name="channel_gain", params=ChannelGain, diagnostics=("plane_gain_spread",),
                      null_field="gains", null_value=1.0):

    def fit(self, d, model, ctx):
        k = dg.plane_slopes(d)
        # the slope each site would have without the model's other effects on the shot term
        k = k / ctx.shot_factor(model, d.flat_levels(model.black_dn)).mean(axis=0)
        g = k / k.mean()
        return Fit(ChannelGain(gains=[float(x) for x in g]), K=float(k.mean()))

    def to_profile(self, p, model):
        fs = model.full_scale_dn
        return ProfileTerm(beta1=[float(model.K * g / fs) for g in p.gains])

    def from_base(self, beta1_sites):
        b1 = float(np.mean(beta1_sites))
        if np.ptp(beta1_sites) > 0:
            return ChannelGain(gains=[float(x) for x in beta1_sites / b1])
        return None
