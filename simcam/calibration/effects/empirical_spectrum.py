"""``empirical_spectrum``: the measured spectrum of temporal row offsets that wander from row to row, for
a row residual no named effect describes.

Physics. ``row_noise`` gives every row of every frame an independent offset: along the rows its
sequence is white. The row reference of many sensors carries flicker (1/f) noise instead, so the
offset of a row is close to its neighbours' and drifts slowly down the frame (J. R. Janesick, *Photon
Transfer*, SPIE 2007, ch. 9; EMVA 1288 Release 4.0, sec. 8, reads line patterns from spectrograms along
the rows and columns, the view applied here to the temporal row offsets; A. Abdelhamed, *Noise
Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 3: noise components
fitted to measured statistics). The row means' variance
(``row_mean_excess``) cannot tell the two apart; their lag-1 autocorrelation along the rows
(``row_mean_lag1``, darks: 0 for white row noise) can, and nothing in the vocabulary proposes it, so
the loop adds this *empirical* component and the report says it is not in the vocabulary, with its
family: row, temporal, additive (present in darks), not exposure-dependent.

Fit. From the dark temporal residuals' row means (each frame's mean removed): their frame-averaged
periodogram less the pixel noise's share and less a white part where a Whittle fit keeps one beside a
power law or a first-order low-pass (:mod:`simcam.calibration.row_spectrum`; that part is ``row_noise``'s,
which is refitted to it), averaged in bands evenly spaced in log frequency; bins of a periodic line
(``periodic_pattern``'s) are left out. The power at frequency 0 (the frame's mean offset, which
the row means of a frame cannot show) is measured on the dark frames' means. A spectrum the Whittle fit
finds white (likelihood ratio of the coloured model against a white one at most 25) is no coloured
component: the fit is null and says so (the white offsets are ``row_noise``'s).

Profile. ``{type: empirical_spectrum, axis: row, frequencies, power, dc_power}`` (cycles per row; powers
on normalised raw squared, ``power_dn2 / (white - black)^2``): the noise stage draws each frame's row
offsets by spectral synthesis (:class:`simcam.noise.effects.empirical.EmpiricalSpectrum`).
"""

from __future__ import annotations

import numpy as np

from ..row_spectrum import COLOURED_LR
from .card import EffectCard, EffectParams, ProfileTerm, quantity


class EmpiricalSpectrum(EffectParams):
    frequencies: list = quantity("cycles/row", "band frequencies of the measured spectrum of the row offsets")
    power_dn2: list = quantity("DN^2", "the spectrum at those frequencies (a periodogram level: white offsets of "
                               "variance v have v)")
    dc_power_dn2: float = quantity("DN^2", "the spectrum at frequency 0 (the frame's mean offset, from the dark "
                                   "frames' means)", default=0.0)
    axis: str = quantity("", "the line the offset is shared along (row)", scale=None, default="row")
    coloured_lr: float | None = quantity("", "likelihood ratio of the coloured spectrum against a white one (fits "
                                         "only)", default=None)


def lines_of(p: EmpiricalSpectrum) -> int:
    """The number of rows the spectrum was measured on (its lowest band starts at one cycle per frame)."""
    return max(int(round(1.0 / float(p.frequencies[0]))), 8) if p.frequencies else 8


def variance_dn2(p: EmpiricalSpectrum) -> float:
    """Variance of one row's offset (DN^2) on a frame of the measured height."""
    from ...noise.effects.empirical import spectrum_variance

    if not p.power_dn2 or max(p.power_dn2) <= 0:  # a frame offset alone is not a row component
        return 0.0
    return spectrum_variance(p.frequencies, p.power_dn2, lines_of(p), p.dc_power_dn2)


class EmpiricalSpectrumCard(EffectCard, name="empirical_spectrum", params=EmpiricalSpectrum,
                            diagnostics=("row_mean_lag1",), marginal_rank=11,
                            family="row, temporal, additive (present in darks), not exposure-dependent"):

    def fit(self, d, model, ctx):
        from ..row_spectrum import coloured_table, row_mean_residuals, row_spectrum_of

        spec = row_spectrum_of(d)
        lr = None if spec is None else float(spec.lr_coloured)
        table = coloured_table(row_mean_residuals(d), spec) if spec is not None and spec.coloured else None
        if table is None:  # too few rows, or white row offsets (row_noise's)
            return EmpiricalSpectrum(frequencies=[0.5], power_dn2=[0.0], coloured_lr=lr)
        return EmpiricalSpectrum(frequencies=table[0], power_dn2=table[1], dc_power_dn2=table[2], coloured_lr=lr)

    def null_reason(self, p):
        if p.coloured_lr is not None and p.coloured_lr <= COLOURED_LR:
            return (f"the dark row means' spectrum is white (likelihood ratio {p.coloured_lr:.3g} against a white "
                    f"spectrum, <= {COLOURED_LR:g}): row offsets of row_noise, not a coloured component")
        return None

    def marginal(self, p, v, lin, model):
        return v + variance_dn2(p)

    def dark_variance_dn2(self, p):
        return variance_dn2(p)

    def is_null(self, p):
        return variance_dn2(p) <= 0.0

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        f, s = np.asarray(p.frequencies, float), np.asarray(p.power_dn2, float)
        return (f"frequencies = {f.size} bands from {f.min():.3g} to {f.max():.3g} cycles/row; power_dn2 = "
                f"from {s[0]:.3g} to {s[-1]:.3g} DN^2 (row offsets' sd {np.sqrt(variance_dn2(p)):.3g} DN); "
                f"dc_power_dn2 = {p.dc_power_dn2:.3g} DN^2; axis = {p.axis}"
                + ("" if p.coloured_lr is None else f"; coloured_lr = {p.coloured_lr:.3g}"))

    def to_profile(self, p, model):
        fs2 = model.full_scale_dn ** 2
        return ProfileTerm(effect={"type": self.name, "axis": p.axis, "frequencies": [float(x) for x in p.frequencies],
                                   "power": [float(x) / fs2 for x in p.power_dn2],
                                   "dc_power": float(p.dc_power_dn2) / fs2})

    def from_profile(self, entry, full_scale_dn):
        if entry.get("axis", "row") != "row":
            raise ValueError("the loop reads an empirical_spectrum entry only along the rows (axis: row)")
        sc = float(entry.get("scale", 1.0)) ** 2
        return EmpiricalSpectrum(frequencies=[float(x) for x in entry["frequencies"]],
                                 power_dn2=[float(x) * full_scale_dn ** 2 * sc for x in entry["power"]],
                                 dc_power_dn2=float(entry["power"][0] if entry.get("dc_power") is None
                                                    else entry["dc_power"]) * full_scale_dn ** 2 * sc)
