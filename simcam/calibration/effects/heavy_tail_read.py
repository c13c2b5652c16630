"""``heavy_tail_read``: read noise with a heavier tail than a Gaussian (Tukey lambda).

Physics. Source-follower flicker and random-telegraph noise give CMOS read noise a tail heavier
than the Gaussian of the Poisson-Gaussian model (A. Abdelhamed, *Noise Modelling for Smartphone
Cameras*, PhD dissertation, York University, 2020, ch. 2, read noise; EMVA 1288 Release 4.0, sec. 2,
where the dark noise sigma_d is only a variance). Following ELD (Wei et al., CVPR 2020), the read
noise *is* a Tukey-lambda variable with shape ``lam`` (lam < 0.14: heavier than Gaussian), scaled to
the read variance: the variance bookkeeping is unchanged, the pixel marginal is no longer
Gaussian (no closed-form density).

Fit. Indirect inference through the full model (quantisation and all): the lam whose simulated dark
tail mass (``dark_tail_mass``) and PPCC shape (``dark_ppcc_lambda``, Filliben 1975) jointly match the
data, on a grid over [-0.45, 0.14]; needs darks. The fit reads the tail the *rest* of the model leaves,
so it is repeated whenever another effect joins the model (``refit_on_change``): an effect that also
makes dark tails (quantisation steps, telegraph pixels, hot pixels' shot noise) would otherwise leave
the read noise's tail fitted to the part it now explains.

Profile. ``{type: heavy_tail_read, lam, scale}`` with ``scale = read / sqrt(var(TukeyLambda(lam)))``
on normalised raw, and the base's beta2 = 0 (the read noise moved into the effect); reading it back,
the read variance is the base's plus ``(scale (white - black))^2 var(TukeyLambda(lam))``.
"""

from __future__ import annotations

from math import gamma

import numpy as np

from .card import DeclaredProfileCard, EffectParams, ProfileTerm, quantity
from .indirect import indirect_fit_joint

#: grid of the indirect fit (lam = 0.14 is nearly Gaussian; below -0.45 the variance diverges at -0.5)
GRID = (-0.45, -0.35, -0.25, -0.15, -0.05, 0.05, 0.14)


def tukey_var(lam: float) -> float:
    """Variance of the standard Tukey-lambda distribution (finite for lam > -1/2)."""
    if abs(lam) < 1e-9:
        return np.pi ** 2 / 3
    return 2.0 / lam ** 2 * (1.0 / (1 + 2 * lam) - gamma(lam + 1) ** 2 / gamma(2 * lam + 2))


class HeavyTailRead(EffectParams):
    lam: float = quantity("", "Tukey-lambda shape of the read noise (dimensionless; 0.14 ~ Gaussian, smaller: heavier tail)",
                          profile="lam")


class HeavyTailReadCard(DeclaredProfileCard, name="heavy_tail_read", params=HeavyTailRead,
                        diagnostics=("dark_tail_mass", "dark_ppcc_lambda"), gaussian=False, needs_darks=True,
                        refit_on_change=True):

    def fit(self, d, model, ctx):
        lam = indirect_fit_joint(d, model, self.name, lambda g: HeavyTailRead(lam=float(g)), list(GRID),
                                 ("dark_tail_mass", "dark_ppcc_lambda"), ctx.dark_specs, ctx.seed, ctx.simulate)
        return HeavyTailRead(lam=float(np.clip(lam, -0.45, 0.14)))

    def to_profile(self, p, model):
        """``{type, lam, scale}`` and beta2 = 0: the read noise moves into the effect."""
        entry = super().to_profile(p, model).effect
        entry["scale"] = float(model.read_dn / np.sqrt(tukey_var(p.lam)) / model.full_scale_dn)
        return ProfileTerm(effect=entry, beta2=0.0)

    def profile_read_dn(self, entry, full_scale_dn, read_dn):
        return float(np.sqrt(read_dn ** 2 + (entry["scale"] * full_scale_dn) ** 2 * tukey_var(entry["lam"])))
