"""``adc_dnl``: an ADC whose codes have unequal widths (differential non-linearity).

Physics. A real ADC's transition levels sit off their ideal places: code k spans
``[k - 1/2 + u_k, k + 1/2 + u_(k+1))`` DN instead of ``[k - 1/2, k + 1/2)``. Its differential
non-linearity is ``DNL_k = u_(k+1) - u_k`` LSB, the code's width minus one (IEEE Std 1241-2010,
sec. 4.1.3; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University,
2020, ch. 2, quantisation noise). A histogram of dark or flat frames then shows codes that are too
frequent (wide) and too rare (narrow), "missing codes" in the extreme, which the uniform quantiser of
the Poisson-Gaussian model (EMVA 1288 Release 4.0, sec. 2) does not make. The noise stage's
``adc_dnl`` draws the transition offsets ``u_k ~ N(0, dnl_sigma^2)`` LSB once per sensor.

Fit. ``code_width_spread`` (the histogram test: each code's count ``c_k`` against ``s_k``, the value at
the code of a least-squares quadratic through its six neighbours' counts, weights ``1/2 - j^2/14`` at
``j = +-1, +-2, +-3``; Poisson part taken off) measures ``E[(c_k - s_k)^2 / s_k^2]``. To first order
``(c_k - s_k) / s_k = DNL_k - sum_j w_j DNL_(k+j)``; with independent offsets, written in the ``u``'s,
its variance is ``(219/49) dnl_sigma^2`` (the sum of the squared coefficients). What a uniform quantiser
leaves (the quadratic's bias on a bent histogram) is in the bootstrap of the current model (its mean,
``FitContext.sim_mean``), so ``dnl_sigma^2 = (value - sim_mean) 49 / 219``.

It is the model's ADC. Its codes are the model's (``LoopModel.q``: one DN, or the ``quantization``
card's step): a coarse ADC has unequal codes as a fine one does, its transition levels off by fractions of
its own code, and the histogram test reads it on the used codes' lattice (``code_histogram``). Beside
``quantization`` both are kept: the step is the quantiser's, the unequal widths this card's (the noise
stage applies ``adc_dnl`` first; its codes are on the quantiser's grid, which leaves them unchanged).

Profile. ``{type: adc_dnl, range_dn, offset_dn, bits, dnl_sigma, step_dn}``: the ADC on normalised raw
(range ``white - black``, the mean black level as the codes' offset, enough codes of ``step_dn`` DN for
the white level).
"""

from __future__ import annotations

import math

import numpy as np

from .card import EffectCard, EffectParams, ProfileTerm, quantity

#: variance of a code's relative count deviation per dnl_sigma^2 (module docstring)
WIDTH_VARIANCE_PER_SIGMA2 = 219.0 / 49.0


class AdcDnl(EffectParams):
    dnl_sigma: float = quantity("LSB", "standard deviation of the ADC's transition offsets (LSB; DNL std = "
                                "sqrt(2) times it)")


class AdcDnlCard(EffectCard, name="adc_dnl", params=AdcDnl, diagnostics=("code_width_spread",),
                 null_field="dnl_sigma"):

    def fit(self, d, model, ctx):
        excess = float(ctx.value) - float(ctx.sim_mean)
        if not math.isfinite(excess) or excess <= 0:
            return AdcDnl(dnl_sigma=0.0)
        return AdcDnl(dnl_sigma=float(min(math.sqrt(excess / WIDTH_VARIANCE_PER_SIGMA2), 2.0)))

    def to_profile(self, p, model):
        step = float(model.q)
        bits = int(min(max(math.ceil(math.log2(float(model.white_dn) / step + 1.0)), 1), 20))
        return ProfileTerm(effect={"type": "adc_dnl", "range_dn": float(model.full_scale_dn),
                                   "offset_dn": float(np.mean(model.black_dn)), "bits": bits,
                                   "dnl_sigma": float(p.dnl_sigma), "step_dn": step})

    def from_profile(self, entry, full_scale_dn):
        return AdcDnl(dnl_sigma=float(entry["dnl_sigma"]))
