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

Oblique patterns. An interference whose frequency is not a multiple of the line rate advances its
phase by a fraction of a period from one row to the next: the bands are tilted, and row or column
means average them away. ``frame_spectrum_peak`` (the largest line off the axes of the whitened 2-D
spectrum of the residuals, averaged over 128 x 128 blocks and frames) proposes the 2-D form: its
peak gives the wave vector (refined to 1/8 bin in both directions by the blocks' summed projection
power), A^2 the mean over blocks and frames of the squared complex projection minus its noise bias
(each block has its own phase: tiles of a mosaic and frames alike). Both forms are candidates where
both kinds of diagnostic propose the effect.

Profile. ``{type: periodic_pattern, amplitude, period_px, axis: rows | columns, cross_frequency,
random_phase: true}``, amplitude on normalised raw, ``amplitude_dn / (white - black)``;
``cross_frequency`` (cycles per pixel along the other axis) is 0 for bands along an axis.
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
    cross_frequency: float | None = quantity("1/px", "frequency along the other axis (cycles per pixel; None: "
                                                     "bands along the axis)", default=None)


class PeriodicPatternCard(EffectCard, name="periodic_pattern", params=PeriodicPattern, null_field="amplitude_dn",
                          diagnostics=("row_spectrum_peak", "col_spectrum_peak", "frame_spectrum_peak"),
                          marginal_rank=20):
    def variants(self, proposed_by):
        # the bands along an axis (the strongest 1-D spectrum) and the 2-D form, where both kinds propose it
        one_d = [d for d in proposed_by if d.name != "frame_spectrum_peak"]
        two_d = [d for d in proposed_by if d.name == "frame_spectrum_peak"]
        return one_d[:1] + two_d[:1]

    def fit(self, d, model, ctx):
        """Sinusoid in the row (or column) means of the temporal residual: peak of the whitened
        periodogram, frequency refined to 1/40 bin, amplitude^2 from the per-frame sine/cosine
        projections minus their noise bias, frames weighted by the inverse square of their noise level.
        From ``frame_spectrum_peak``: :func:`fit_oblique`."""
        if ctx.diagnostic == "frame_spectrum_peak":
            return fit_oblique(d)
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
                                   "cross_frequency": float(p.cross_frequency or 0.0), "random_phase": True})

    def from_profile(self, entry, full_scale_dn):
        return PeriodicPattern(amplitude_dn=float(entry["amplitude"]) * full_scale_dn, period_px=float(entry["period_px"]),
                               axis="row" if entry.get("axis", "rows") == "rows" else "col",
                               cross_frequency=float(entry["cross_frequency"]) if entry.get("cross_frequency") else None)


def fit_oblique(d) -> PeriodicPattern:
    """The 2-D form from :func:`simcam.calibration.diagnostics.block_spectrum` (module docstring)."""
    p = dg.block_spectrum(d)
    res, side = dg.spectrum_blocks(d)
    q = np.array(p, dtype=np.float64)
    q[dg.axis_lines(side)] = 0.0
    iy, ix = np.unravel_index(int(np.argmax(q)), q.shape)
    fy0 = (iy if iy <= side // 2 else iy - side) / side
    fx0 = (ix if ix <= side // 2 else ix - side) / side
    blocks = list(dg.iter_blocks(res, side))
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    step = 1.0 / (8 * side)

    def projections(fy, fx):
        e = np.exp(-2j * np.pi * (fy * yy + fx * xx))
        return [np.tensordot(b, e, axes=([1, 2], [0, 1])) for b in blocks]  # per block: (n,) complex

    best = (-1.0, fy0, fx0)
    for fy in fy0 + step * np.arange(-4, 5):
        for fx in fx0 + step * np.arange(-4, 5):
            pw = float(sum(np.sum(np.abs(c) ** 2) for c in projections(fy, fx)))
            if pw > best[0]:
                best = (pw, fy, fx)
    _, fy, fx = best
    npx = side * side
    a2, w = 0.0, 0.0
    for b, c in zip(blocks, projections(fy, fx)):
        amp2 = (2.0 / npx) ** 2 * np.abs(c) ** 2  # |2/N sum b e^{-i phi}|^2 = A^2 for b = A sin(phi + phase)
        bias = 4.0 * np.var(b, axis=(1, 2)) / npx  # its expectation on white noise of that variance
        a2 += float(np.sum(amp2 - bias))
        w += b.shape[0]
    A = float(np.sqrt(max(a2 / w, 0.0)))
    if fy < 0 or (fy == 0 and fx < 0):
        fy, fx = -fy, -fx
    if abs(fy) >= abs(fx):
        return PeriodicPattern(amplitude_dn=A, period_px=float(1.0 / fy), axis="row", cross_frequency=float(fx))
    s = 1.0 if fx > 0 else -1.0
    return PeriodicPattern(amplitude_dn=A, period_px=float(1.0 / abs(fx)), axis="col", cross_frequency=float(fy * s))
