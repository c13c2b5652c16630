"""``empirical_lines``: the measured spectral lines of a periodic fixed column pattern, for a column
pattern no named effect describes.

Physics. ``column_fpn`` gives every column an independent offset (a white spectrum along the
columns). Some column patterns are periodic instead: column ADCs interleaved in groups, with an offset
mismatch between the converters, repeat every few columns; so do patterns of the column multiplexer.
EMVA 1288 Release 4.0, sec. 8, shows them as lines in the horizontal spectrogram of the DSNU (A.
Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2,
fixed-pattern noise).
``col_fpn_spectrum_peak`` (the largest bin of the fixed column profile's periodogram over its median)
sees them, and nothing in the vocabulary proposes a periodic *fixed* pattern (``periodic_pattern``
has a fresh phase every frame), so the loop adds this *empirical* component and the report says it is
not in the vocabulary, with its family: column, fixed, additive (present in darks), not
exposure-dependent.

Fit. From the column profiles of the even- and of the odd-frame dark mean maps
(:func:`simcam.calibration.diagnostics.column_profile_spectrum`): the lines are the bins whose
periodogram exceeds :data:`LINE_FACTOR` times its median (the largest bin always where the darks'
statistic proposed the card; the Nyquist bin,
a period of two columns, is a CFA column's offset and is left to the black level), and each line's
variance is its bin's share of the two profiles' covariance less the median share (the white part:
``column_fpn``, DSNU averaged down the columns): temporal noise, independent between the halves,
drops out. A line of variance ``v`` is a cosine of amplitude ``sqrt(2 v)`` at the bin's frequency.

Gain part. Interleaved converters (or column amplifiers) that differ in gain as well as in offset
make a column pattern that grows with the light: absent from the darks, proportional to the signal
in the flats (EMVA 1288 Release 4.0, sec. 8: the horizontal spectrogram of the PRNU).
``flat_col_spectrum_peak`` sees it in the flats' even/odd-frame column profiles less the darks',
per unit of signal (:func:`simcam.calibration.diagnostics.flat_column_gain_spectrum`). Its lines are
chosen as the darks' are (and its strongest where that stands further out than the darks'); a line's
relative gain amplitude is ``sqrt(2 v)`` of its bin's share of the even/odd covariance of the relative
profiles less the median share (PRNU and temporal noise averaged down the columns), and the phase of
the gain against the offset is that of the two profiles' Fourier coefficients (the in-phase and
opposite cases of one converter being brighter in the dark and the light, or the other way round).

Profile. ``{type: empirical_lines, axis: column, lines: [[frequency, amplitude], ...]}``, frequency
in cycles per pixel, amplitude on normalised raw, ``amplitude_dn / (white - black)``; a line with a gain
part is ``[frequency, amplitude, gain, phase]`` (relative gain amplitude, radians). The noise stage
draws the phases once per sensor (:class:`simcam.noise.effects.empirical.EmpiricalLines`).
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, quantity

#: a bin of the fixed column profile's periodogram is a line when it exceeds this many times the median
#: (for a white pattern the ratio is exponential over log 2: beyond 20 with probability 1e-6 per bin)
LINE_FACTOR = 20.0


class EmpiricalLines(EffectParams):
    lines_dn: list = quantity("DN", "spectral lines of the column pattern: [frequency (cycles per pixel), amplitude "
                              "of the offset's cosine (DN)], or with [..., relative amplitude of the gain's cosine, "
                              "its phase against the offset's (radians)]")
    axis: str = quantity("", "the line the offset is shared along (column)", scale=None, default="column")


def line_offset(line) -> float:
    """A line's offset amplitude (DN): its second entry."""
    return float(line[1])


def _gain(line) -> tuple[float, float]:
    return (float(line[2]), float(line[3])) if len(line) == 4 else (0.0, 0.0)


def _line_variance(share: np.ndarray, i: int, median: float) -> float:
    """A bin's share of the even/odd-frame profile covariance less the median share (the white part)."""
    return max(float(share[i]) - median, 0.0)


class EmpiricalLinesCard(EffectCard, name="empirical_lines", params=EmpiricalLines,
                         diagnostics=("col_fpn_spectrum_peak", "flat_col_spectrum_peak"), gaussian=False,
                         fixed_pattern=True, marginal_rank=71,
                         family="column, fixed, additive (present in darks), not exposure-dependent"):

    def family_of(self, p):
        if any(_gain(line)[0] > 0 for line in p.lines_dn):
            return ("column, fixed, additive (present in darks) and multiplicative (grows with the signal), "
                    "not exposure-dependent")
        return self.family

    def fit(self, d, model, ctx):
        spec = dg.column_profile_spectrum(d)
        if spec is None:
            return EmpiricalLines(lines_dn=[])
        p, share, w = spec
        k = np.arange(1, p.size + 1)
        inner = k < w / 2  # (not the Nyquist bin)
        if not inner.any():
            return EmpiricalLines(lines_dn=[])
        med_s = float(np.median(share))
        chosen = (p > LINE_FACTOR * float(np.median(p))) & inner
        dpeak = int(np.argmax(np.where(inner, p, -np.inf)))
        if getattr(ctx, "diagnostic", None) != "flat_col_spectrum_peak":  # proposed by the darks: their strongest line
            chosen[dpeak] = True
        gspec = dg.flat_column_gain_spectrum(d) if d.darks else None
        gain_chosen = np.zeros_like(chosen)
        if gspec is not None:
            gain_chosen = (gspec.power > LINE_FACTOR * float(np.median(gspec.power))) & inner
            gpeak = int(np.argmax(np.where(inner, gspec.power, -np.inf)))
            # the flats' strongest gain line too where it stands further out than the darks' peak
            if gspec.power[gpeak] / np.median(gspec.power) > p[dpeak] / np.median(p):
                gain_chosen[gpeak] = True
        lines = []
        g_med = float(np.median(gspec.share)) if gspec is not None else 0.0
        for i in np.flatnonzero(chosen | gain_chosen):
            a = float(np.sqrt(2.0 * _line_variance(share, i, med_s)))
            g = float(np.sqrt(2.0 * _line_variance(gspec.share, i, g_med))) if gain_chosen[i] else 0.0
            if g > 0:
                delta = float(np.angle(gspec.gain[i] * np.conj(gspec.offset[i]))) if a > 0 else 0.0
                lines.append([float(k[i]) / w, a, g, delta])
            elif a > 0:
                lines.append([float(k[i]) / w, a])
        return EmpiricalLines(lines_dn=lines)

    def is_null(self, p):
        return not any(line_offset(line) > 0 or _gain(line)[0] > 0 for line in p.lines_dn)

    def marginal(self, p, v, lin, model):
        # a line of offset a and gain g (phase delta between them) on the signal x: variance over the columns
        # (a^2 + (g x)^2) / 2 + a g x cos(delta)
        for line in p.lines_dn:
            a, (g, delta) = line_offset(line), _gain(line)
            v = v + (a * a + (g * lin) ** 2) / 2 + a * g * lin * np.cos(delta)
        return v

    def to_profile(self, p, model):
        from .card import ProfileTerm

        fs = model.full_scale_dn
        return ProfileTerm(effect={"type": self.name, "axis": p.axis,
                                   "lines": [[float(line[0]), line_offset(line) / fs, *(_gain(line) if len(line) == 4 else ())]
                                             for line in p.lines_dn]})

    def from_profile(self, entry, full_scale_dn):
        if entry.get("axis", "column") != "column":
            raise ValueError("the loop reads an empirical_lines entry only along the columns (axis: column)")
        return EmpiricalLines(lines_dn=[[float(line[0]), float(line[1]) * full_scale_dn, *map(float, line[2:])]
                                        for line in entry["lines"]])

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)

        def one(line):
            g, delta = _gain(line)
            gain = f" + gain {g:.3g} at {delta:+.2f} rad" if g > 0 else ""
            return f"period {1 / line[0]:.3g} px: {line_offset(line):.3g} DN{gain}"

        shown = ", ".join(one(line) for line in p.lines_dn[:4])
        more = f" and {len(p.lines_dn) - 4} more" if len(p.lines_dn) > 4 else ""
        return f"lines_dn = {len(p.lines_dn)} line(s) ({shown}{more}); axis = {p.axis}"
