"""``spatial_correlation``: crosstalk of the read noise between same-colour (or adjacent) neighbours.

Physics. Shared readout circuitry and electrical crosstalk couple the read noise of neighbouring
pixels of one CFA plane: the noise stage filters it inside each plane with the separable kernel
[a, 1, a] x [a, 1, a], renormalised to keep its variance, so the in-plane lag-1 correlation is
2a / (1 + 2a^2) and lag-2 a^2 / (1 + 2a^2), and different-colour neighbours stay independent
(EMVA 1288 Release 4.0, sec. 8: spatially non-white temporal noise; A. Abdelhamed, *Noise Modelling
for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, crosstalk). Shot noise
stays white. The variance, hence the closed-form marginal, is unchanged.

Fit. Indirect inference: the a whose simulated in-plane lag-1 correlation of dark residuals
(``lag1_corr``; diluted by quantisation noise, hence no closed form) matches the data, on a grid
over [0, 0.5]; needs darks. Proposed by ``adjacent_corr``, the mosaic kernel is fitted the same way
on that statistic; where both the in-plane lags and ``adjacent_corr`` propose the effect, both
kernels are candidates and the held-out comparison picks one. ``adjacent_corr`` also proposes the
``total`` form (the noise stage's ``domain: total``: electrical crosstalk after the pixel couples the
shot noise of flats as much as the read noise of darks, with the cross kernel ``(1 - 4c, c)`` of a
charge-conserving coupling, variance kept), fitted the same way over c in [0, 0.22]; beside the read
form it lets the held-out flats decide whether their adjacent-pixel correlation belongs to the same
coupling (``total``), to the photo-electrons alone (``charge_crosstalk``) or to nothing.

Profile. ``{type: spatial_correlation, coefficient}``: the loop's ``a`` (same kernel).
"""

from __future__ import annotations

import numpy as np

from .card import DeclaredProfileCard, EffectParams, quantity
from .indirect import indirect_fit

#: grid of the indirect fit
GRID = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
#: grid of c for the ``total`` form (cross kernel: 4c < 1)
GRID_TOTAL = (0.0, 0.02, 0.04, 0.07, 0.1, 0.14, 0.18, 0.22)


class SpatialCorrelation(EffectParams):
    a: float = quantity("", "coupling of the [a, 1, a] kernel of the read noise (dimensionless, 0 to 0.5)",
                        profile="coefficient")
    neighbours: str | None = quantity("", "which neighbours the kernel couples: adjacent (on the mosaic); None: "
                                      "same-colour ones (inside each CFA plane)", scale=None, default=None)
    domain: str | None = quantity("", "what the kernel couples: total (all the noise at read-out, cross kernel "
                                  "(1 - 4a, a)); None: the read noise", scale=None, default=None)


class SpatialCorrelationCard(DeclaredProfileCard, name="spatial_correlation", params=SpatialCorrelation, null_field="a",
                             diagnostics=("lag1_corr", "lag2_corr", "adjacent_corr"), needs_darks=True):

    def variants(self, proposed_by):
        # the same-colour kernel is seen first by the in-plane lags, the mosaic kernel by adjacent_corr (and,
        # weakly, by the in-plane lags: a^2 at 2 px): both are fitted where both kinds propose it
        adjacent = [d for d in proposed_by if d.name == "adjacent_corr"]
        in_plane = [d for d in proposed_by if d.name != "adjacent_corr"]
        return adjacent[:1] + [(d, "total") for d in adjacent[:1]] + in_plane[:1]

    def fit(self, d, model, ctx):
        hood = "adjacent" if ctx.diagnostic == "adjacent_corr" else None
        if ctx.form == "total":
            a = indirect_fit(d, model, self.name,
                             lambda g: SpatialCorrelation(a=float(g), neighbours="adjacent", domain="total"),
                             list(GRID_TOTAL), "adjacent_corr", ctx.dark_specs, ctx.seed, ctx.simulate)
            return SpatialCorrelation(a=float(np.clip(a, 0.0, GRID_TOTAL[-1])), neighbours="adjacent", domain="total")
        a = indirect_fit(d, model, self.name, lambda g: SpatialCorrelation(a=float(g), neighbours=hood), list(GRID),
                         "adjacent_corr" if hood else "lag1_corr", ctx.dark_specs, ctx.seed, ctx.simulate)
        return SpatialCorrelation(a=float(np.clip(a, 0.0, 0.5)), neighbours=hood)

    def to_profile(self, p, model):
        term = super().to_profile(p, model)
        if p.neighbours is not None:
            term.effect["neighbours"] = p.neighbours
        if p.domain is not None:
            term.effect["domain"] = p.domain
        return term

    def from_profile(self, entry, full_scale_dn):
        hood = entry.get("neighbours", "same_colour")
        dom = entry.get("domain", "read")
        return SpatialCorrelation(a=float(entry["coefficient"]), neighbours=None if hood == "same_colour" else str(hood),
                                  domain=None if dom == "read" else str(dom))
