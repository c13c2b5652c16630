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
While the data's codes are coarser than the model's (``adc_step`` more than :data:`CODE_LATTICE_RATIO`
times ``LoopModel.q``: the coarse step not yet modelled) the candidate is the step and the widths
together: ``quantization`` is its prerequisite, fitted first (the loop's ``_fit_candidate``), and the
candidate adds both. Fitted on 1-DN codes the widths would be relative to codes the data does not
have: beside them the step's own candidate was refuted on a 6-DN ADC (the independent simulator's
quantisation + DNL case at ``--seed 2034``: the model then took a black offset and a heavy-tailed read
noise for what the quantiser's codes do to the darks); left out until the step was in, a black offset
took their place on a 16-DN ADC (the same case at ``--seed 2035``, ISO 3200). Without the step in the
model the fit is null.

Profile. ``{type: adc_dnl, range_dn, offset_dn, bits, dnl_sigma, step_dn}``: the ADC on normalised raw
(range ``white - black``, the mean black level as the codes' offset, enough codes of ``step_dn`` DN for
the white level).
"""

from __future__ import annotations

import math

import numpy as np

from .card import EffectCard, EffectParams, ProfileTerm, quantity

#: the fit is null while the data's code spacing exceeds the model's codes by more than this factor
CODE_LATTICE_RATIO = 1.5

#: variance of a code's relative count deviation per dnl_sigma^2 (module docstring)
WIDTH_VARIANCE_PER_SIGMA2 = 219.0 / 49.0


def coarser_codes(d, model) -> float | None:
    """The data's code spacing (``adc_step``, DN) where it exceeds the model's codes by more than
    :data:`CODE_LATTICE_RATIO` (the coarse step not yet modelled), else None."""
    from .. import diagnostics as dg

    step = dg.adc_step(d)
    return step if step > CODE_LATTICE_RATIO * float(model.q) else None


class AdcDnl(EffectParams):
    dnl_sigma: float = quantity("LSB", "standard deviation of the ADC's transition offsets (LSB; DNL std = "
                                "sqrt(2) times it)")
    coarser_codes_dn: float | None = quantity("DN", "only on a null fit: the data's code spacing, coarser than the "
                                              "model's codes", default=None)


class AdcDnlCard(EffectCard, name="adc_dnl", params=AdcDnl, diagnostics=("code_width_spread",),
                 null_field="dnl_sigma"):

    def fit(self, d, model, ctx):
        step = coarser_codes(d, model)
        if step is not None:  # the step first (module docstring)
            return AdcDnl(dnl_sigma=0.0, coarser_codes_dn=step)
        excess = float(ctx.value) - float(ctx.sim_mean)
        if not math.isfinite(excess) or excess <= 0:
            return AdcDnl(dnl_sigma=0.0)
        return AdcDnl(dnl_sigma=float(min(math.sqrt(excess / WIDTH_VARIANCE_PER_SIGMA2), 2.0)))

    def prerequisite(self, d, model):
        """``quantization`` while the data's codes are coarser than the model's (module docstring)."""
        if "quantization" in model.effects or coarser_codes(d, model) is None:
            return None
        return "quantization"

    def null_reason(self, p):
        if p.coarser_codes_dn:
            return (f"the data's codes are {p.coarser_codes_dn:.3g} DN apart, coarser than the model's: unequal "
                    "widths are read on the quantiser's codes, so its step (quantization) comes first")
        return None

    def to_profile(self, p, model):
        step = float(model.q)
        bits = int(min(max(math.ceil(math.log2(float(model.white_dn) / step + 1.0)), 1), 20))
        return ProfileTerm(effect={"type": "adc_dnl", "range_dn": float(model.full_scale_dn),
                                   "offset_dn": float(np.mean(model.black_dn)), "bits": bits,
                                   "dnl_sigma": float(p.dnl_sigma), "step_dn": step})

    def from_profile(self, entry, full_scale_dn):
        return AdcDnl(dnl_sigma=float(entry["dnl_sigma"]))
