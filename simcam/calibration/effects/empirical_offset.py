"""``empirical_offset``: a measured per-frame column offset, for a residual no named effect explains.

Physics. Some sensors add an offset to each *column* of each frame, drawn anew every frame (temporal
column noise: column-parallel ADCs or amplifiers with their own 1/f noise and a shared reference,
EMVA 1288 Release 4.0, sec. 8, the column component of the temporal noise; A. Abdelhamed, *Noise
Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 3: noise components
fitted to measured statistics). None of the named effects makes it: ``column_fpn`` is the fixed part
of the column offsets, ``row_noise`` the per-frame part of the rows. ``col_temporal_excess`` (the
variance of each frame's column means of the temporal residual over its white-noise share) sees it,
and nothing else in the vocabulary proposes it, so the loop adds this *empirical* component and the
report says it is not in the vocabulary, with its family: column, temporal, additive (present in the
darks), not exposure-dependent.

Fit. From the darks (else the flats): each frame's column means of the temporal residual (the
frame's mean taken off). Their variance is the column offset's plus the white part ``pixel variance /
H``; what exceeds the white part is the offset's variance s^2. Its *law* is the measured one: the 33 quantiles (at
probabilities 0, 1/32, ..., 1) of the column means, centred and shrunk towards their median by
``s / sd(column means)`` (the Gaussian deconvolution of the white part; exact when both are
Gaussian), so a skewed or heavy-tailed column noise keeps its shape.

Profile. The noise stage's ``{type: empirical_offset, axis: column, temporal: true, quantiles}``
(quantiles on normalised raw; drawn by inverse transform every frame).
"""

from __future__ import annotations

import numpy as np

from .card import EffectCard, EffectParams, quantity

#: quantiles kept of the measured law
N_QUANTILES = 33


def quantile_table_moments(q) -> tuple[float, float]:
    """(mean, variance) of the law whose quantiles at equally spaced probabilities 0..1 are ``q``:
    between consecutive quantiles the law is uniform (linear interpolation of the quantile function)."""
    q = np.asarray(q, dtype=np.float64)
    a, b = q[:-1], q[1:]
    m = float(np.mean((a + b) / 2))
    m2 = float(np.mean((a * a + a * b + b * b) / 3))
    return m, max(m2 - m * m, 0.0)


class EmpiricalOffset(EffectParams):
    quantiles_dn: list = quantity("DN", "quantiles of one column's offset in one frame at probabilities 0, 1/32, "
                                  "..., 1 (DN, mean 0)")
    axis: str = quantity("", "the line the offset is shared along (column)", scale=None, default="column")


class EmpiricalOffsetCard(EffectCard, name="empirical_offset", params=EmpiricalOffset,
                          diagnostics=("col_temporal_excess",), gaussian=False,
                          family="column, temporal, additive (present in darks), not exposure-dependent"):

    def fit(self, d, model, ctx):
        res = d.temporal_residuals("dark") or d.temporal_residuals("flat")
        means, excess = [], []
        for r in res:
            cm = r.mean(axis=1)  # (frames, W): each frame's column means
            cm = cm - cm.mean(axis=1, keepdims=True)
            means.append(cm.ravel())
            excess.append(float(np.mean(cm * cm)) - float(np.var(r)) / r.shape[1])
        m = np.concatenate(means)
        s2 = max(float(np.mean(excess)), 0.0)
        sd = float(np.std(m))
        if not (s2 > 0 and sd > 0):
            return EmpiricalOffset(quantiles_dn=[0.0] * N_QUANTILES)
        q = np.quantile(m, np.linspace(0.0, 1.0, N_QUANTILES))
        q = (q - np.median(m)) * min(np.sqrt(s2) / sd, 1.0)
        q -= quantile_table_moments(q)[0]
        return EmpiricalOffset(quantiles_dn=[float(x) for x in q])

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        q = np.asarray(p.quantiles_dn, dtype=np.float64)
        sd = np.sqrt(quantile_table_moments(q)[1])
        return (f"quantiles_dn = {q.size} quantiles, sd {sd:.3g} DN, from {q[0]:.3g} to {q[-1]:.3g} DN, median "
                f"{float(np.interp(0.5, np.linspace(0, 1, q.size), q)):.3g} DN; axis = {p.axis}")

    def is_null(self, p):
        return quantile_table_moments(p.quantiles_dn)[1] <= 0.0

    def dark_variance_dn2(self, p):
        return quantile_table_moments(p.quantiles_dn)[1]

    def to_profile(self, p, model):
        from .card import ProfileTerm

        fs = model.full_scale_dn
        return ProfileTerm(effect={"type": self.name, "axis": p.axis, "temporal": True,
                                   "quantiles": [float(x) / fs for x in p.quantiles_dn]})

    def from_profile(self, entry, full_scale_dn):
        if entry.get("map") is not None or not entry.get("temporal", False) or entry.get("axis", "pixel") != "column":
            raise ValueError("the loop reads an empirical_offset entry only as a temporal column offset given by "
                             "quantiles (axis: column, temporal: true)")
        return EmpiricalOffset(quantiles_dn=[float(x) * full_scale_dn * float(entry.get("scale", 1.0))
                                             for x in entry["quantiles"]], axis="column")
