"""``charge_crosstalk``: photo-electrons shared with the adjacent pixels before read-out.

Physics. Electrons generated near a pixel's edge diffuse into its neighbours (on a Bayer mosaic the
adjacent pixels are of the other colours) before they are collected, so the charge, *with its shot
noise*, is filtered by ``(1 - 4c) delta + c (4 adjacent)`` and the read noise is added after it
(A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020,
ch. 2, crosstalk; J. Nakamura (ed.), *Image Sensors and Signal Processing for Digital Still
Cameras*, CRC 2006, sec. 3.3, optical and electrical crosstalk). Charge is conserved: a flat's
shot-noise variance drops by ``f = (1 - 4c)^2 + 4c^2`` (the photon-transfer slope reads ``K f``,
not the system gain K: EMVA 1288 Release 4.0, sec. 2, takes each pixel's shot noise as Poisson and
independent of its neighbours), adjacent pixels' shot noise gets the correlation
``2c(1 - 4c) / f``, and dark frames (no photo-electrons) are untouched. The read-side coupling of
dark noise is ``spatial_correlation`` (``neighbours: adjacent``), seen in darks and flats alike.

Fit. Closed form from ``flat_adjacent_corr`` (lag-1 correlation of the flats' temporal residuals
on the mosaic): its excess over the current model's bootstrap mean, divided by the shot share of
the flats' temporal variance (``1 - dark variance / flat variance``), is the shot-noise correlation
``2c(1 - 4c) / f``, solved for c (monotone on [0, 0.11]); the system gain is re-estimated as
``K / f``.

Profile. ``{type: charge_crosstalk, coefficient}`` (the noise stage's effect, diagonal 0).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from .card import DeclaredProfileCard, EffectParams, Fit, quantity

#: the fit's range of c: the shot-noise correlation 2c(1-4c)/f grows monotonically up to c ~ 0.11
C_MAX = 0.11


def variance_factor(c: float) -> float:
    """Factor on the shot-noise variance, ``(1 - 4c)^2 + 4c^2``."""
    return (1 - 4 * c) ** 2 + 4 * c ** 2


def shot_correlation(c: float) -> float:
    """Lag-1 correlation of adjacent pixels' shot noise after the sharing, ``2c(1 - 4c) / f``."""
    return 2 * c * (1 - 4 * c) / variance_factor(c)


class ChargeCrosstalk(EffectParams):
    c: float = quantity("%", "share of a pixel's photo-electrons going to each adjacent pixel (dimensionless; shown "
                             "in %)", scale=100.0, profile="coefficient")


class ChargeCrosstalkCard(DeclaredProfileCard, name="charge_crosstalk", params=ChargeCrosstalk,
                          diagnostics=("flat_adjacent_corr",), null_field="c", marginal_rank=5):

    def fit(self, d, model, ctx):
        res = d.temporal_residuals("flat")
        v_flat = float(np.mean([np.mean(r * r) for r in res])) if res else 0.0
        share = 1.0 - model.var_dark_dn2 / v_flat if v_flat > 0 else 0.0
        rho = (ctx.value - ctx.sim_mean) / share if share > 0.05 else 0.0
        if not rho > 0:
            return Fit(ChargeCrosstalk(c=0.0), K=model.K)
        rho = min(rho, shot_correlation(C_MAX))
        c = float(brentq(lambda x: shot_correlation(x) - rho, 0.0, C_MAX))
        return Fit(ChargeCrosstalk(c=c), K=float(model.K / variance_factor(c)))

    def marginal(self, p, v, lin, model):
        # the base's shot term K g_c x drops by the variance factor
        from ...noise.base import site_map

        gmap = site_map(model.gains(), lin.shape[-2:], name="channel gain", dtype=np.float64)
        return v - (1.0 - variance_factor(p.c)) * model.K * gmap * lin

    def linear_signal(self, p, y, model):
        """The expected charge image whose sharing is ``y`` (fixed-point iteration x <- x + y - S x, which
        converges for 8c < 1: the sharing's eigenvalues lie in [1 - 8c, 1])."""
        if p.c == 0 or y.ndim < 2:
            return y
        from ...noise.effects.correlation import charge_share

        x = np.array(y, dtype=np.float64)
        for _ in range(12):
            x += y - charge_share(x, float(p.c)).astype(np.float64)
        return x

    def to_profile(self, p, model):
        term = super().to_profile(p, model)
        term.effect["diagonal"] = 0.0
        return term
