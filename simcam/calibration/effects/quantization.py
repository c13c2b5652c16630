"""``quantization``: an ADC coarser than the DN grid (codes ``step_dn`` apart).

Physics. The ADC maps the voltage to integer codes; a camera that drops low bits, or applies a
digital gain after the ADC, leaves only every ``step``-th DN occupied. Uniform quantisation adds
``step^2 / 12`` to the temporal variance (EMVA 1288 Release 4.0, sec. 2: quantisation noise
sigma_q^2 = 1/12 DN^2 for a 1-DN step; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
dissertation, York University, 2020, ch. 2, quantisation noise). The step is the model's ADC
(``LoopModel.q``, 1 DN without this effect), so its variance is part of the base ADC term of the
marginal variance and of the read-noise bookkeeping, not a term of its own.

Fit. ``code_occupancy``: the median gap between the codes used in the central 98 % of the darks (else,
or where the darks sit on one code, the dimmest flat), at least 1 DN. The read noise is then measured
again through the quantiser: ``step^2 / 12`` is the quantisation variance only when the signal before
the ADC is spread over many codes (Sheppard's correction; EMVA 1288 R4.0 sec. 2 states it for that
case). Dark frames with a read noise below the step sit on one or two codes, and their temporal variance
depends on where the dark level falls between two codes (a 0.9-DN read noise under a 10-DN step, the
dark level 1 DN above a decision threshold: 11.5 DN^2, where the additive bookkeeping gives 0.81 + 8.33
= 9.1 DN^2 and, read backwards from 11.5 DN^2, a read noise of about 1.7 DN instead of 0.9). So the read
noise is the one whose simulated darks (the loop's bootstrap: the current model with the quantiser,
every other effect in it) have the measured mean temporal dark variance: indirect inference on a grid of
read noises (Gourieroux, Monfort & Renault 1993), interpolated.

Profile. ``{type: quantization, range_dn, step_dn, offset_dn}``: the ADC on normalised raw, range
``white - black``, the step, and the mean black level as the codes' offset.
"""

from __future__ import annotations

import numpy as np

from .card import DeclaredProfileCard, EffectParams, Fit, ProfileTerm, quantity


class Quantization(EffectParams):
    step_dn: float = quantity("DN", "distance between adjacent ADC codes (DN, >= 1)", profile="step_dn", profile_default=1.0)


#: read noises (as a share of the read noise the additive bookkeeping gives, at least the step) simulated
#: by the indirect fit, and the sensors simulated at each
READ_GRID = np.geomspace(0.03, 1.5, 12)
READ_REPS = 2


def dark_temporal_variance(darks) -> float:
    """Mean over the pixels of the per-pixel temporal variance of dark sequences (n, H, W), pooled with
    weights n - 1 (DN^2)."""
    num = dof = 0.0
    for a in darks:
        if a.shape[0] >= 2:
            num += float(np.mean(np.var(a, axis=0, ddof=1))) * (a.shape[0] - 1)
            dof += a.shape[0] - 1
    return num / dof if dof else float("nan")


class QuantizationCard(DeclaredProfileCard, name="quantization", params=Quantization, diagnostics=("code_occupancy",)):

    def fit(self, d, model, ctx):
        from ..diagnostics import adc_step

        p = Quantization(step_dn=adc_step(d))
        if p.step_dn <= 1.0 or ctx.simulate is None or not ctx.dark_specs or not d.darks:
            return p
        target = dark_temporal_variance(d.darks)
        m = model.with_effect(self.name, p)
        top = max(m.read_dn, p.step_dn)
        grid = top * READ_GRID
        sim = np.empty(grid.size)
        for j, read in enumerate(grid):
            mj = m.copy()
            mj.read_dn = float(read)
            mj.set_dark_variance_from_read()
            # common random numbers: the same sensors at every grid point (a smooth, monotone curve)
            sim[j] = np.mean([dark_temporal_variance(ctx.simulate(mj, ctx.dark_specs, np.random.default_rng([ctx.seed, 7, r])))
                              for r in range(READ_REPS)])
        order = np.argsort(sim)
        return Fit(p, read_dn=float(np.interp(target, sim[order], grid[order])))

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": "quantization", "range_dn": float(model.full_scale_dn),
                                   "step_dn": float(p.step_dn), "offset_dn": float(np.mean(model.black_dn))})

    def is_null(self, p):
        return float(p.step_dn) <= 1.0
