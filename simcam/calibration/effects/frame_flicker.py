"""``frame_flicker``: a per-frame gain on the illumination (light-source flicker, exposure jitter).

Physics. The photon flux of frame f is ``mu_e (1 + n_f)``, ``n_f ~ N(0, sigma^2)`` drawn anew every
frame and shared by all its pixels: it needs light (darks do not show it) and adds ``(sigma x)^2``
to a pixel's temporal variance, x the linear signal above black (DN). EMVA 1288 Release 4.0,
sec. 6, requires the irradiation to be stable between frames for the photon-transfer method; this
effect models a set that is not (A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
dissertation, York University, 2020, ch. 2: the photon shot noise is the only temporal variation of
the signal the base model allows).

Fit. ``frame_mean_jitter`` (frame-to-frame variance of the flat frame means, as half their mean
square successive difference, over the signal squared): sigma^2 is its excess over the mean of the
bootstrap replicates of the current model. A level drifting slowly over the sequence adds little to
it (``frame_mean_drift`` sees that, and no named effect makes it), so a drift is not
fitted as flicker.

Profile. ``{type: frame_flicker, sigma}``: the same dimensionless sigma.
"""

from __future__ import annotations

import numpy as np

from .card import EffectParams, GainSigmaCard, quantity


class FrameFlicker(EffectParams):
    sigma: float = quantity("%", "rms relative deviation of a frame's illumination gain (dimensionless; shown in %)",
                            scale=100.0, profile="sigma")


class FrameFlickerCard(GainSigmaCard, name="frame_flicker", params=FrameFlicker, diagnostics=("frame_mean_jitter",),
                       marginal_rank=30):

    def fit(self, d, model, ctx):
        excess = ctx.value - ctx.sim_mean
        return FrameFlicker(sigma=float(np.sqrt(max(excess, 0.0))))
