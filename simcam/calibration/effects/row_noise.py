"""``row_noise``: a per-frame offset of each row (horizontal banding).

Physics. Row-wise readout shares a reference and a clock between the pixels of a row, so each row of
each frame gets an offset ``~ N(0, sigma^2)`` drawn anew every frame: temporal noise, the same for
every pixel of the row (ELD, Wei et al., CVPR 2020; EMVA 1288 Release 4.0, sec. 4 and 8: the row
component of a spatial variance; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
dissertation, York University, 2020, ch. 2, read noise). It adds sigma^2 to every pixel's temporal
variance, dark or lit, so the read noise is what is left of the dark variance once it (and the
quantisation) is taken off.

Fit. Variance of the row means of the temporal residual (darks, else flats) minus the pixel
variance's share ``var / W``; a modelled row-wise periodic pattern (``periodic_pattern``, axis row),
already part of that variance, is taken off (amplitude^2 / 2), so the effect is refitted when one is
added after it. Beside a modelled coloured row component
(``empirical_spectrum``: offsets that wander from row to row), whose addition refits this one, the
variance is the white part the spectral fit of the dark row means keeps beside the coloured one
(:mod:`simcam.calibration.row_spectrum`; none when no white part is significant).

Profile. ``{type: row_noise, sigma}`` with sigma on normalised raw, ``sigma_dn / (white - black)``.
"""

from __future__ import annotations

import numpy as np

from .card import EffectParams, OffsetSigmaCard, quantity


class RowNoise(EffectParams):
    sigma_dn: float = quantity("DN", "rms of a row's offset in one frame (DN)", profile="sigma", per_full_scale=True)


class RowNoiseCard(OffsetSigmaCard, name="row_noise", params=RowNoise, diagnostics=("row_mean_excess",), marginal_rank=10,
                  refit_after=("empirical_spectrum", "periodic_pattern")):

    def fit(self, d, model, ctx):
        res = d.temporal_residuals("dark") or d.temporal_residuals("flat")
        vals = []
        for r in res:
            rm = r.mean(axis=2)
            vals.append(np.var(rm, axis=1).mean() - np.var(r) / r.shape[2])
        s2 = float(np.mean(vals))
        per = model.effects.get("periodic_pattern")
        if per is not None and per.axis == "row":  # a modelled row-wise sinusoid is already part of it
            s2 -= per.amplitude_dn ** 2 / 2
        if "empirical_spectrum" in model.effects:  # the wandering part of the row offsets is that component's
            from ..row_spectrum import row_spectrum_of
            from .empirical_spectrum import variance_dn2

            spec = row_spectrum_of(d)
            if spec is not None:  # the white part its spectral fit kept beside the coloured one (or none)
                return RowNoise(sigma_dn=float(np.sqrt(spec.w)) if spec.white_part else 0.0)
            s2 -= variance_dn2(model.effects["empirical_spectrum"])
        return RowNoise(sigma_dn=float(np.sqrt(max(s2, 0.0))))

    def dark_variance_dn2(self, p):
        return p.sigma_dn ** 2
