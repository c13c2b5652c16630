"""``column_fpn``: column fixed-pattern noise, a fixed offset per column.

Physics. Column-parallel readout gives every column its own amplifier and ADC offset: an offset
``~ N(0, sigma^2)`` per column, drawn once per sensor and the same in every frame (EMVA 1288
Release 4.0, sec. 4 and 8: the column component of the DSNU; A. Abdelhamed, *Noise Modelling for
Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, fixed-pattern noise). An
offset after the response, it adds sigma^2 to a pixel's variance about the plane mean.

Fit. ``col_fpn_excess``: sigma^2 is the covariance of the column profiles of the even- and
odd-frame mean maps (darks, else the longest flat); temporal column noise, independent between the
halves, drops out. The variance of the spectral lines of a periodic column pattern in the model
(``empirical_lines``, sum of a^2 / 2) is not this effect's: it is taken off, and the fit is repeated
when those lines join the model.

Profile. ``{type: column_fpn, sigma}`` with sigma on normalised raw, ``sigma_dn / (white - black)``.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectParams, OffsetSigmaCard, quantity
from .empirical_lines import line_offset


class ColumnFpn(EffectParams):
    sigma_dn: float = quantity("DN", "rms of the per-column offset (DN)", profile="sigma", per_full_scale=True)


class ColumnFpnCard(OffsetSigmaCard, name="column_fpn", params=ColumnFpn, diagnostics=("col_fpn_excess",),
                    fixed_pattern=True, marginal_rank=70, refit_after=("empirical_lines",)):

    def fit(self, d, model, ctx):
        """sigma_col^2 = covariance of the column profiles of the even- and odd-frame mean maps, less the
        variance of the model's periodic column lines."""
        (ca, _va, _h), (cb, _vb, _) = dg.column_profiles(d)
        lines = model.effects.get("empirical_lines")
        s2 = float(np.mean((ca - ca.mean()) * (cb - cb.mean())))
        s2 -= sum(line_offset(line) ** 2 / 2 for line in lines.lines_dn) if lines is not None else 0.0
        return ColumnFpn(sigma_dn=float(np.sqrt(max(s2, 0.0))))
