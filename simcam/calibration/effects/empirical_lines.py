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
periodogram exceeds :data:`LINE_FACTOR` times its median (the largest bin always; the Nyquist bin,
a period of two columns, is a CFA column's offset and is left to the black level), and each line's
variance is its bin's share of the two profiles' covariance less the median share (the white part:
``column_fpn``, DSNU averaged down the columns): temporal noise, independent between the halves,
drops out. A line of variance ``v`` is a cosine of amplitude ``sqrt(2 v)`` at the bin's frequency.

Profile. ``{type: empirical_lines, axis: column, lines: [[frequency, amplitude], ...]}``, frequency
in cycles per pixel, amplitude on normalised raw, ``amplitude_dn / (white - black)``; the noise stage
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
    lines_dn: list = quantity("DN", "spectral lines of the column offsets: [frequency (cycles per pixel), amplitude "
                              "of the cosine (DN)]")
    axis: str = quantity("", "the line the offset is shared along (column)", scale=None, default="column")


class EmpiricalLinesCard(EffectCard, name="empirical_lines", params=EmpiricalLines,
                         diagnostics=("col_fpn_spectrum_peak",), gaussian=False, fixed_pattern=True,
                         marginal_rank=71,
                         family="column, fixed, additive (present in darks), not exposure-dependent"):

    def fit(self, d, model, ctx):
        spec = dg.column_profile_spectrum(d)
        if spec is None:
            return EmpiricalLines(lines_dn=[])
        p, share, w = spec
        k = np.arange(1, p.size + 1)
        inner = k < w / 2  # (not the Nyquist bin)
        if not inner.any():
            return EmpiricalLines(lines_dn=[])
        med_p, med_s = float(np.median(p)), float(np.median(share))
        peak = int(np.argmax(np.where(inner, p, -np.inf)))
        chosen = (p > LINE_FACTOR * med_p) & inner
        chosen[peak] = True
        lines = []
        for i in np.flatnonzero(chosen):
            v = float(share[i]) - med_s
            if v > 0:
                lines.append([float(k[i]) / w, float(np.sqrt(2.0 * v))])
        return EmpiricalLines(lines_dn=lines)

    def is_null(self, p):
        return not any(a > 0 for _f, a in p.lines_dn)

    def marginal(self, p, v, lin, model):
        return v + sum(a * a / 2 for _f, a in p.lines_dn)

    def to_profile(self, p, model):
        from .card import ProfileTerm

        fs = model.full_scale_dn
        return ProfileTerm(effect={"type": self.name, "axis": p.axis,
                                   "lines": [[float(f), float(a) / fs] for f, a in p.lines_dn]})

    def from_profile(self, entry, full_scale_dn):
        if entry.get("axis", "column") != "column":
            raise ValueError("the loop reads an empirical_lines entry only along the columns (axis: column)")
        return EmpiricalLines(lines_dn=[[float(f), float(a) * full_scale_dn] for f, a in entry["lines"]])

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        shown = ", ".join(f"period {1 / f:.3g} px: {a:.3g} DN" for f, a in p.lines_dn[:4])
        more = f" and {len(p.lines_dn) - 4} more" if len(p.lines_dn) > 4 else ""
        return f"lines_dn = {len(p.lines_dn)} line(s) ({shown}{more}); axis = {p.axis}"
