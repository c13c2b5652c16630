"""``quantization``: an ADC coarser than the DN grid (codes ``step_dn`` apart).

Physics. The ADC maps the voltage to integer codes; a camera that drops low bits, or applies a
digital gain after the ADC, leaves only every ``step``-th DN occupied. Uniform quantisation adds
``step^2 / 12`` to the temporal variance (EMVA 1288 Release 4.0, sec. 2: quantisation noise
sigma_q^2 = 1/12 DN^2 for a 1-DN step; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
dissertation, York University, 2020, ch. 2, quantisation noise). The step is the model's ADC
(``LoopModel.q``, 1 DN without this effect), so its variance is part of the base ADC term of the
marginal variance and of the read-noise bookkeeping, not a term of its own.

Fit. ``code_occupancy``: the median gap between the codes used in the central 98 % of the darks
(else the dimmest flat), at least 1 DN.

Profile. ``{type: quantization, range_dn, step_dn, offset_dn}``: the ADC on normalised raw, range
``white - black``, the step, and the mean black level as the codes' offset.
"""

from __future__ import annotations

import numpy as np

from .card import DeclaredProfileCard, EffectParams, ProfileTerm, quantity


class Quantization(EffectParams):
    step_dn: float = quantity("DN", "distance between adjacent ADC codes (DN, >= 1)", profile="step_dn", profile_default=1.0)


class QuantizationCard(DeclaredProfileCard, name="quantization", params=Quantization, diagnostics=("code_occupancy",)):

    def fit(self, d, model, ctx):
        src = d.darks or sorted(d.flats, key=lambda a: float(a.mean()))[:1]
        v = np.concatenate([s.ravel() for s in src])
        lo, hi = np.percentile(v, [1, 99])
        codes = np.unique(np.round(v[(v >= lo) & (v <= hi)]))
        gaps = np.diff(codes)
        step = float(np.median(gaps)) if gaps.size else 1.0
        return Quantization(step_dn=max(step, 1.0))

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": "quantization", "range_dn": float(model.full_scale_dn),
                                   "step_dn": float(p.step_dn), "offset_dn": float(np.mean(model.black_dn))})

    def is_null(self, p):
        return float(p.step_dn) <= 1.0
