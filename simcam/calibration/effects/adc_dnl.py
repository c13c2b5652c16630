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

The transition the darks straddle. Beside a coarse step, darks whose values sit on the black's code and
one neighbour (``diagnostics.split_on_black_code``) tell where the one transition between those codes lies
relative to the dark level (EMVA 1288 Release 4.0, sec. 2: such darks give the dark level and variance
only as bounds), and that transition decides every dark statistic: the share of dark values on each code,
their temporal variance, the row and column means. A draw of this sensor's offsets puts it anywhere within
its code. The diagnostic ``dark_code_split`` (the share of dark values off the black's code) proposes this
card too, and the fit then measures the transition (``edge_dn``): the level below which the model's own
analogue dark values (the current model without its ADC, drawn by the loop's bootstrap: their CDF at its
1-DN codes' transitions, interpolated on the probit scale) hold the share the data has on the lower code
(IEEE Std 1241-2010, sec. 4.1.3: a transition level from the cumulative histogram of a known input). Read
noise and transition are the model's pair that reproduces the split; neither alone is measured (the model's
read noise is kept, at most :data:`SPLIT_READ_MAX` of a code: more would spread darks over three). Without
it an independent simulator's 12-DN ADC under a 0.9-DN dark noise (``benchmarks/loop_independent.py``,
quantisation + DNL, ISO 100, seeds 2036 and 2038) kept its held-out structured KL at 11.4 → 10.7 and
10.8 → 9.6 once the step was modelled; with it, 11.4 → 0.022 and 10.8 → 0.008.

Profile. ``{type: adc_dnl, range_dn, offset_dn, bits, dnl_sigma, step_dn, edges_dn}``: the ADC on normalised
raw (range ``white - black``, the mean black level as the codes' offset, enough codes of ``step_dn`` DN for
the white level) and the measured transition, if any, in DN.
"""

from __future__ import annotations

import math

import numpy as np

from .card import EffectCard, EffectParams, Fit, ProfileTerm, quantity

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
    edge_dn: float | None = quantity("DN", "the measured transition level the darks straddle, on a coarse ADC whose "
                                     "codes they sit on two of", default=None)


#: bootstrap sensors whose analogue darks locate the transition the darks straddle
EDGE_REPS = 2
#: darks that sit on two codes hold a dark noise of at most about a quarter of a code (a Gaussian's 99 %
#: within the two codes' span): a larger read noise in the model (a quantiser's fit of the split darks'
#: temporal variance under ideal transitions) is taken down to it with the measured transition
SPLIT_READ_MAX = 0.25


def dark_split_edge(d, model, ctx) -> tuple[float, float] | None:
    """The transition level (DN) between the two codes the darks sit on (module docstring) and the read noise
    (DN) it goes with (the model's, at most :data:`SPLIT_READ_MAX` of a code), or None: the model's ADC not
    coarse, the darks not split, no bootstrap."""
    from .. import diagnostics as dg

    step = float(model.q)
    if step <= 1.0 or ctx.simulate is None or not ctx.dark_specs or not d.darks or d.black_dn is None:
        return None
    darks = np.concatenate([np.asarray(a, np.float64).ravel() for a in d.darks])
    black = float(np.mean(d.black_dn))
    if not dg.split_on_black_code(darks, black, step):
        return None
    code = dg.black_code(darks, black, step)[1]  # on the data's codes
    up, down = float(np.mean(darks > code + step / 2)), float(np.mean(darks < code - step / 2))
    lower = code if up >= down else code - step  # the lower of the two codes
    share = float(np.mean(darks < lower + step / 2))
    if not 0.0 < share < 1.0:
        return None
    analogue = model.copy()  # the model's dark values before its ADC (simcam.calibration.simulate.ADC_EFFECTS)
    for name in ("quantization", "adc_dnl"):
        analogue.effects.pop(name, None)
    read = min(float(model.read_dn), SPLIT_READ_MAX * step)
    analogue.read_dn = read
    analogue.set_dark_variance_from_read()
    values = np.sort(np.round(np.concatenate([np.asarray(a, np.float64).ravel() for r in range(EDGE_REPS)
                                              for a in ctx.simulate(analogue, ctx.dark_specs,
                                                                    np.random.default_rng([ctx.seed, 11, r]))])))
    # the analogue CDF is known at the 1-DN codes' transitions, P(x < k + 1/2) = P(code <= k); interpolated on
    # the probit scale (exact for a Gaussian: the 1-DN knots are as wide as the read noise)
    from scipy.special import ndtri

    ks = np.arange(values[0], values[-1])
    cdf = np.searchsorted(values, ks, side="right") / values.size
    keep = np.concatenate([[True], np.diff(cdf) > 0]) & (cdf > 0) & (cdf < 1)
    if keep.sum() < 2:
        return None
    edge = float(np.interp(ndtri(share), ndtri(cdf[keep]), ks[keep] + 0.5))
    return float(np.clip(edge, lower + 0.01 * step, lower + 0.99 * step)), read


class AdcDnlCard(EffectCard, name="adc_dnl", params=AdcDnl, diagnostics=("code_width_spread", "dark_code_split"),
                 null_field="dnl_sigma"):

    def fit(self, d, model, ctx):
        step = coarser_codes(d, model)
        if step is not None:  # the step first (module docstring)
            return AdcDnl(dnl_sigma=0.0, coarser_codes_dn=step)
        sigma = 0.0  # the widths' spread from the histogram test; proposed by dark_code_split, the edge alone
        if ctx.diagnostic != "dark_code_split":
            excess = float(ctx.value) - float(ctx.sim_mean)
            if math.isfinite(excess) and excess > 0:
                sigma = float(min(math.sqrt(excess / WIDTH_VARIANCE_PER_SIGMA2), 2.0))
        split = dark_split_edge(d, model, ctx)
        if split is None:
            return AdcDnl(dnl_sigma=sigma)
        edge, read = split
        p = AdcDnl(dnl_sigma=sigma, edge_dn=edge)
        return Fit(p, read_dn=read)  # the read noise the edge was measured with

    def is_null(self, p):
        return float(p.dnl_sigma) <= 0.0 and p.edge_dn is None

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
        effect = {"type": "adc_dnl", "range_dn": float(model.full_scale_dn), "offset_dn": float(np.mean(model.black_dn)),
                  "bits": bits, "dnl_sigma": float(p.dnl_sigma), "step_dn": step}
        if p.edge_dn is not None:
            effect["edges_dn"] = [float(p.edge_dn)]
        return ProfileTerm(effect=effect)

    def from_profile(self, entry, full_scale_dn):
        edges = entry.get("edges_dn") or []
        return AdcDnl(dnl_sigma=float(entry["dnl_sigma"]), edge_dn=float(edges[0]) if edges else None)
