"""``periodic_pattern``: a sinusoidal banding along the rows or the columns, random phase per frame.

Physics. Interference from switching supplies or clocks couples into the readout as a sinusoid
along the readout order, ``A sin(2 pi i / period + phase_f)`` with a fresh phase every frame: a
narrow line in the spectrum of the row (or column) means (EMVA 1288 Release 4.0, sec. 8: the
horizontal and vertical spectrograms, where periodic patterns show as peaks; A. Abdelhamed, *Noise
Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, pattern noise).
Temporal, it adds A^2 / 2 to every pixel's variance, dark or lit.

Fit. The peak of the whitened periodogram of the line means of the temporal residual
(``row_spectrum_peak`` along the rows, ``col_spectrum_peak`` along the columns, which also gives the
axis), its frequency refined to 1/40 bin; A^2 from the per-frame sine / cosine projections minus
their noise bias, frames weighted by the inverse square of their noise level.

Profile. ``{type: periodic_pattern, amplitude, period_px, axis: rows | columns, random_phase: true}``,
amplitude on normalised raw, ``amplitude_dn / (white - black)``.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, ProfileTerm, quantity


class PeriodicPattern(EffectParams):
    amplitude_dn: float = quantity("DN", "amplitude of the sinusoid (DN)")
    period_px: float = quantity("px", "period along the axis (pixels)")
    axis: str = quantity("", "'row': along the row index (horizontal bands), 'col': along the column index",
                         scale=None, default="row")


class PeriodicPatternCard(EffectCard, name="periodic_pattern", params=PeriodicPattern, null_field="amplitude_dn",
                          diagnostics=("row_spectrum_peak", "col_spectrum_peak"), marginal_rank=20):
    def fit(self, d, model, ctx):
        """Sinusoid in the row (or column) means of the temporal residual: peak of the whitened
        periodogram, frequency refined to 1/40 bin, amplitude^2 from the per-frame sine/cosine
        projections minus their noise bias, frames weighted by the inverse square of their noise level."""
        axis_name = "row" if ctx.diagnostic == "row_spectrum_peak" else "col"
        axis = 2 if axis_name == "row" else 1
        lm = np.concatenate(dg._line_means("all", axis, d))  # (frames, L)
        lm = lm - lm.mean(axis=1, keepdims=True)
        L = lm.shape[1]
        p = dg.whitened_periodogram(d, axis)
        k = int(np.argmax(p[1:])) + 1
        noise = np.median(np.abs(np.fft.rfft(lm, axis=1))[:, 1:] ** 2, axis=1)  # per-frame noise level
        w_f = 1.0 / noise
        idx = np.arange(L)
        best = (-1.0, k / L)
        for f in np.linspace((k - 0.5) / L, (k + 0.5) / L, 41):
            c, s_ = np.cos(2 * np.pi * f * idx), np.sin(2 * np.pi * f * idx)
            pw = float(np.sum(w_f * ((lm @ c) ** 2 + (lm @ s_) ** 2)))
            if pw > best[0]:
                best = (pw, f)
        f = best[1]
        c, s_ = np.cos(2 * np.pi * f * idx), np.sin(2 * np.pi * f * idx)
        a = 2 / L * (lm @ c)
        b = 2 / L * (lm @ s_)
        resid = lm - a[:, None] * c - b[:, None] * s_
        bias = 4 * np.var(resid, axis=1) / L  # E[a^2 + b^2] = A^2 + 4 sigma^2 / L for white noise sigma^2
        w = w_f ** 2
        A2 = float(np.sum(w * (a * a + b * b - bias)) / np.sum(w))
        return PeriodicPattern(amplitude_dn=float(np.sqrt(max(A2, 0.0))), period_px=float(1.0 / f), axis=axis_name)

    def marginal(self, p, v, lin, model):
        return v + p.amplitude_dn ** 2 / 2

    def dark_variance_dn2(self, p):
        return p.amplitude_dn ** 2 / 2

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": "periodic_pattern", "amplitude": float(p.amplitude_dn / model.full_scale_dn),
                                   "period_px": float(p.period_px), "axis": "rows" if p.axis == "row" else "columns",
                                   "random_phase": True})

    def from_profile(self, entry, full_scale_dn):
        return PeriodicPattern(amplitude_dn=float(entry["amplitude"]) * full_scale_dn, period_px=float(entry["period_px"]),
                               axis="row" if entry.get("axis", "rows") == "rows" else "col")
