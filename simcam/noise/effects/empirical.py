"""Empirical components: what a calibration measured but no named effect describes.

When a significant residual matches no effect of the vocabulary, the calibration loop can add
an *empirical* component fitted from the data itself (A. Abdelhamed, *Noise Modelling for
Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 3: noise models fitted to
measured statistics): the measured map, the measured distribution, the measured code table, the
measured field. Each is usable by the noise stage and in profiles like a named effect. Maps are
``FILE.npz#KEY`` references (:mod:`simcam.noise.maps`); distributions are quantile tables
sampled by inverse transform (``np.interp`` of uniform draws on the quantiles at equal
probabilities).

* ``empirical_offset`` — an additive offset along ``axis`` (pixel, row, column, frame), fixed
  (a map, or a per-sensor draw from ``quantiles``) or temporal (a fresh draw every frame), plus an
  optional ``rate`` per second of exposure shared by every pixel (a black level that rises with the
  exposure time, without the shot noise of dark charge);
* ``empirical_gain`` — a multiplicative fixed pattern of the expected signal (pixel, row,
  column): a measured PRNU-like map or gain distribution;
* ``empirical_lines`` — a fixed pattern along rows or columns given by its measured spectral lines
  (frequency, amplitude of the offset, and optionally the relative amplitude and phase of a gain on
  the expected signal), phases drawn once per sensor;
* ``empirical_spectrum`` — a temporal additive offset along rows or columns whose sequence has a
  measured power spectrum (row offsets that wander from row to row: 1/f noise of the row reference),
  drawn every frame by spectral synthesis;
* ``empirical_code`` — the ADC's measured transition levels (DN): the code of each value;
* ``empirical_field`` — a smooth measured dark field in normalised raw per second (glow-like),
  with its Poisson shot noise through ``electron``;
* ``empirical_response`` — a response that curves by a different amount in every pixel,
  ``y = x - s_p x^2`` on the noisy value, ``s_p`` a measured map or a per-sensor draw from the
  measured law of the per-pixel strength (``nonlinearity`` with a fixed pattern of its strength).
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np
from pydantic import Field, model_validator

from ...errors import NoiseModelError
from ..maps import fit_to, load_map
from .base import Effect, register_effect
from .dark import _add_poisson_electrons, exposure_of


def draw_quantiles(quantiles, size, rng: np.random.Generator) -> np.ndarray:
    """``size`` draws from the law whose quantiles at probabilities linspace(0, 1, n) are ``quantiles``."""
    q = np.asarray(quantiles, dtype=np.float64)
    return np.interp(rng.random(size), np.linspace(0.0, 1.0, q.size), q)


class _MapOrQuantiles(Effect):
    map: Optional[str] = None
    quantiles: Optional[list[float]] = None
    scale: float = 1.0

    @model_validator(mode="after")
    def _one(self):
        if (self.map is None) == (self.quantiles is None):
            raise ValueError("give exactly one of map (FILE.npz#KEY) or quantiles (a measured distribution)")
        if self.quantiles is not None:
            if len(self.quantiles) < 2 or any(b < a for a, b in zip(self.quantiles, self.quantiles[1:])):
                raise ValueError("quantiles: expected at least 2 non-decreasing values")
        return self

    def _pattern(self, shape, rng, axis) -> np.ndarray:
        if self.map is not None:
            return self.scale * fit_to(load_map(self.map), shape, axis, where=f"effect {self.type!r}")
        n = {"pixel": shape, "row": (shape[0], 1), "column": (1, shape[1])}[axis]
        return (self.scale * draw_quantiles(self.quantiles, n, rng)).astype(np.float32)


@register_effect
class EmpiricalOffset(_MapOrQuantiles):
    """Measured additive offset (normalised raw) along ``axis``; ``temporal``: a fresh draw each frame.

    ``rate`` (normalised raw per second, default 0): every pixel also gets ``rate * t``, t the frame's
    exposure time (a black level that rises with the exposure, e.g. a clamp that self-heating shifts;
    no shot noise, unlike ``dark_current``); with it the noise stage needs the exposure time."""

    type: Literal["empirical_offset"] = "empirical_offset"
    axis: Literal["pixel", "row", "column", "frame"] = "pixel"
    temporal: bool = False
    rate: float = 0.0

    def to_entry(self):
        out = super().to_entry()
        if self.rate == 0:  # no exposure dependence: the entry as before the option existed
            out.pop("rate")
        return out

    @model_validator(mode="after")
    def _axis(self):
        if self.axis == "frame" and not self.temporal:
            raise ValueError("axis: frame needs temporal: true (a fixed frame offset is a black-level offset)")
        if self.temporal and self.map is not None:
            raise ValueError("temporal: a per-frame draw needs quantiles, not a map")
        return self

    def fixed(self, shape, rng):
        return {} if self.temporal else {"offset": self._pattern(shape, rng, self.axis)}

    def frame(self, shape, rng):
        if not self.temporal:
            return {}
        n = {"pixel": shape, "row": (shape[0], 1), "column": (1, shape[1]), "frame": (1, 1)}[self.axis]
        return {"offset": (self.scale * draw_quantiles(self.quantiles, n, rng)).astype(np.float32)}

    def apply(self, x, ctx):
        off = ctx.frame["offset"] if self.temporal else ctx.fixed["offset"]
        x += off[: x.shape[0], : x.shape[1]]  # (H, W), (H, 1), (1, W) or (1, 1)
        if self.rate != 0:
            x += np.float32(self.rate * exposure_of(ctx, self.type))
        return x


@register_effect
class EmpiricalGain(_MapOrQuantiles):
    """Measured multiplicative fixed pattern of the expected signal (values around 1) along ``axis``."""

    type: Literal["empirical_gain"] = "empirical_gain"
    stage = "signal"
    logprob_role = "signal"
    axis: Literal["pixel", "row", "column"] = "pixel"

    def fixed(self, shape, rng):
        return {"gain": self._pattern(shape, rng, self.axis)}

    def apply(self, x, ctx):
        return (x * ctx.fixed["gain"][: x.shape[0], : x.shape[1]]).astype(np.float32)


@register_effect
class EmpiricalLines(Effect):
    """A measured fixed pattern along ``axis`` given by its spectral lines: line index ``i`` (the
    column for ``axis: column``) gets the offset ``sum_j a_j cos(2 pi f_j i + phi_j)`` (normalised raw)
    and, for a line given as ``[f, a, g, delta]``, the gain ``1 + sum_j g_j cos(2 pi f_j i + phi_j +
    delta_j)`` on the expected signal: a pattern that grows with the light (column ADCs interleaved with
    a gain mismatch as well as an offset mismatch; EMVA 1288 Release 4.0, sec. 8, the horizontal
    spectrogram of the PRNU). The phases ``phi_j`` are uniform on [0, 2 pi) and drawn once per sensor;
    ``delta_j`` keeps the measured phase of a line's gain part against its offset part. Each line adds
    ``a_j^2 / 2`` to the variance of the line offsets and keeps its frequency whatever the frame's size
    (a Fourier surrogate: measured amplitudes, random phases; J. Theiler et al., "Testing for
    nonlinearity in time series: the method of surrogate data", Physica D 58, 1992)."""

    type: Literal["empirical_lines"] = "empirical_lines"
    axis: Literal["row", "column"] = "column"
    lines: list[tuple[float, float] | tuple[float, float, float, float]] = Field(min_length=1)
    stack_ok = True
    logprob_role = "offset"

    @model_validator(mode="after")
    def _lines(self):
        for line in self.lines:
            f, a = line[0], line[1]
            if not (0.0 <= f <= 0.5) or not a >= 0.0 or (len(line) == 4 and not 0.0 <= line[2] < 0.5):
                raise ValueError(f"lines: {list(line)}: expected [frequency in cycles per pixel in [0, 0.5], "
                                 "amplitude >= 0] or [frequency, amplitude, relative gain amplitude in [0, 0.5), "
                                 "phase of the gain against the offset (radians)]")
        return self

    @property
    def has_gain(self) -> bool:
        return any(len(line) == 4 and line[2] > 0 for line in self.lines)

    def fixed(self, shape, rng):
        n = shape[0] if self.axis == "row" else shape[1]
        i = np.arange(n, dtype=np.float64)
        out = np.zeros(n)
        gain = np.zeros(n)
        for line in self.lines:
            f, a = line[0], line[1]
            phi = 2 * np.pi * f * i + rng.uniform(0.0, 2 * np.pi)
            out += a * np.cos(phi)
            if len(line) == 4:
                gain += line[2] * np.cos(phi + line[3])
        out = out.astype(np.float32)
        got = {"offset": out[:, None] if self.axis == "row" else out[None, :]}
        if self.has_gain:
            gain = gain.astype(np.float32)
            got["gain"] = gain[:, None] if self.axis == "row" else gain[None, :]
        return got

    def apply(self, x, ctx):
        h, w = x.shape[-2], x.shape[-1]
        x += ctx.fixed["offset"][:h, :w]
        if "gain" in ctx.fixed:
            if ctx.signal is None:
                raise NoiseModelError("empirical_lines with a gain part needs the expected signal")
            x += ctx.fixed["gain"][:h, :w] * ctx.signal
        return x


def spectrum_amplitudes(frequencies, power, n: int, dc_power: float | None = None) -> np.ndarray:
    """``sqrt(S(f_k))`` on the ``rfft`` bins ``f_k = k / n`` of a length-``n`` sequence: the power table
    interpolated linearly in log f, its end values beyond its range; at ``f = 0`` (the frame's mean
    offset) ``dc_power``, or the lowest band's value when None."""
    f = np.fft.rfftfreq(n)
    p = np.asarray(power, np.float64)
    s = np.full(f.size, p[0] if dc_power is None else float(dc_power))
    if f.size > 1:
        s[1:] = np.interp(np.log(f[1:]), np.log(np.asarray(frequencies, np.float64)), p)
    return np.sqrt(np.maximum(s, 0.0))


def spectrum_variance(frequencies, power, n: int = 1024, dc_power: float | None = None) -> float:
    """Variance of one line offset of :class:`EmpiricalSpectrum` on a sequence of ``n`` lines (the mean of
    the interpolated spectrum over the ``n`` frequencies ``k / n`` of the sequence, ``k = 0`` included)."""
    a = spectrum_amplitudes(frequencies, power, n, dc_power) ** 2
    full = np.concatenate((a, a[1:(n + 1) // 2][::-1])) if n > 1 else a
    return float(np.sum(full) / n)


@register_effect
class EmpiricalSpectrum(Effect):
    """A temporal offset shared along each row (``axis: row``; each column for ``axis: column``) whose
    sequence over the rows has the measured power spectrum ``power`` at ``frequencies`` (cycles per
    line, a periodogram level in normalised raw^2: a white sequence of variance v has v at every
    frequency; ``dc_power`` at f = 0, the frame's mean offset: the lowest band's value when not given).
    Every frame draws white normals, filters them by ``sqrt(S(f))`` in the Fourier domain
    and transforms back (spectral synthesis of a Gaussian stationary sequence: D. B. Percival and A. T.
    Walden, *Spectral Analysis for Physical Applications*, Cambridge University Press, 1993, ch. 7;
    the same surrogate as :class:`EmpiricalLines`, drawn anew every frame), so the sequence keeps its
    spectrum whatever the frame's size; ``scale`` multiplies the offsets."""

    type: Literal["empirical_spectrum"] = "empirical_spectrum"
    axis: Literal["row", "column"] = "row"
    frequencies: list[float] = Field(min_length=1)
    power: list[float] = Field(min_length=1)
    dc_power: Optional[float] = Field(default=None, ge=0)
    scale: float = 1.0

    @model_validator(mode="after")
    def _table(self):
        f, p = self.frequencies, self.power
        if len(f) != len(p):
            raise ValueError(f"power: {len(p)} values for {len(f)} frequencies; expected one per frequency")
        if any(not (0.0 < x <= 0.5) for x in f) or any(b <= a for a, b in zip(f, f[1:])):
            raise ValueError("frequencies: expected increasing values in (0, 0.5] (cycles per line)")
        if any(not (x >= 0.0) or not np.isfinite(x) for x in p):
            raise ValueError("power: expected finite values >= 0")
        return self

    def amplitudes(self, n: int) -> np.ndarray:
        """The filter of a sequence of ``n`` lines (:func:`spectrum_amplitudes`)."""
        return spectrum_amplitudes(self.frequencies, self.power, n, self.dc_power)

    def frame(self, shape, rng):
        n = shape[0] if self.axis == "row" else shape[1]
        z = np.fft.rfft(rng.standard_normal(n))
        y = (self.scale * np.fft.irfft(z * self.amplitudes(n), n)).astype(np.float32)
        return {"offset": y[:, None] if self.axis == "row" else y[None, :]}

    def apply(self, x, ctx):
        x += ctx.frame["offset"][: x.shape[0], : x.shape[1]]
        return x


@register_effect
class EmpiricalCode(Effect):
    """The ADC's measured transition levels: ``edges[k]`` (DN) is where code k + ``first_code`` + 1 starts."""

    type: Literal["empirical_code"] = "empirical_code"
    stack_ok = True
    range_dn: float = Field(gt=0)
    offset_dn: float = 0.0
    edges: str | list[float]
    first_code: int = 0

    def fixed(self, shape, rng):
        e = np.asarray(load_map(self.edges) if isinstance(self.edges, str) else self.edges, dtype=np.float64)
        if e.ndim != 1 or e.size < 1 or np.any(np.diff(e) < 0):
            raise NoiseModelError(f"effect {self.type!r}: edges: expected increasing transition levels (DN)")
        return {"edges": e}

    def apply(self, x, ctx):
        analog = x.astype(np.float64) * self.range_dn + self.offset_dn
        code = np.searchsorted(ctx.fixed["edges"], analog, side="right") + self.first_code
        return ((code - self.offset_dn) / self.range_dn).astype(np.float32)


@register_effect
class EmpiricalField(Effect):
    """A measured dark field (normalised raw per second) accumulating over the exposure with its Poisson
    shot noise (``electron``: normalised raw per electron): a low-resolution grid of a smooth field,
    upsampled bilinearly to the frame, or a per-pixel map at least the frame's size (``simcam loop
    --maps``' dark-rate map), of which the frame takes the top-left part."""

    type: Literal["empirical_field"] = "empirical_field"
    field: str | list[list[float]]
    electron: float = Field(gt=0)

    def fixed(self, shape, rng):
        from scipy.ndimage import zoom

        g = np.asarray(load_map(self.field) if isinstance(self.field, str) else self.field, dtype=np.float64)
        if g.ndim != 2 or (g < 0).any():
            raise NoiseModelError(f"effect {self.type!r}: field: expected a 2-D grid of rates >= 0")
        if g.shape[0] >= shape[0] and g.shape[1] >= shape[1]:  # a per-pixel map of the sensor
            return {"rate": g[: shape[0], : shape[1]].copy()}
        full = zoom(g, (shape[0] / g.shape[0], shape[1] / g.shape[1]), order=1, mode="nearest", grid_mode=True)
        return {"rate": full[: shape[0], : shape[1]]}

    def apply(self, x, ctx):
        t = exposure_of(ctx, self.type)
        if t == 0:
            return x
        _add_poisson_electrons(x, ctx.fixed["rate"][: x.shape[0], : x.shape[1]] * t / self.electron, self.electron,
                               ctx)
        return x


@register_effect
class EmpiricalResponse(_MapOrQuantiles):
    """Per-pixel response curvature: ``y = x - s_p x^2`` on the noisy value, ``s_p`` fixed per pixel.

    Physics. The floating-diffusion capacitance and the source follower's gain differ from pixel to
    pixel, so each pixel's charge-to-voltage response bends by its own amount: the flats' fixed
    pattern then grows faster than the signal (a gain's grows in proportion), and its mean over the
    pixels is the sensor's common non-linearity (EMVA 1288 Release 4.0, sec. 6: linearity, measured on
    the mean; sec. 8: the spatial non-uniformity at each level). As ``nonlinearity`` it acts on the
    noisy value (shot and read noise included) and is placed where that effect is.

    Units. Normalised raw above black; ``s_p`` dimensionless (``nonlinearity``'s ``strength`` of
    pixel p), drawn once per sensor from ``quantiles`` (the measured law of the per-pixel strength) or
    read from ``map``; every value within +-0.45 (monotonic below x = 1.1).
    """

    type: Literal["empirical_response"] = "empirical_response"
    logprob_role = "response"
    stack_ok = True

    @model_validator(mode="after")
    def _range(self):
        if self.quantiles is not None and max(abs(self.scale * q) for q in self.quantiles) > 0.45:
            raise ValueError("quantiles: per-pixel strengths must lie within +-0.45 (a monotonic response)")
        return self

    def fixed(self, shape, rng):
        s = self._pattern(shape, rng, "pixel")
        if float(np.max(np.abs(s))) > 0.45:
            raise NoiseModelError(f"effect 'empirical_response': map {self.map}: strengths must lie within +-0.45")
        return {"strength": s}

    def apply(self, x, ctx):
        s = ctx.fixed["strength"][: x.shape[-2], : x.shape[-1]]
        x -= s * x * x
        return x

    def inverse(self, y: np.ndarray, fixed: dict | None = None) -> np.ndarray:
        """``x`` with ``apply(x) = y`` on the monotonic branch (float64), pixel by pixel."""
        y = np.asarray(y, dtype=np.float64)
        s = np.asarray(fixed["strength"], dtype=np.float64)[: y.shape[-2], : y.shape[-1]]
        return 2.0 * y / (1.0 + np.sqrt(np.maximum(1.0 - 4.0 * s * y, 0.0)))

    def log_slope(self, x: np.ndarray, fixed: dict | None = None) -> np.ndarray:
        """``log |dy/dx|`` at ``x`` (float64), the Jacobian term of ``log_prob``."""
        x = np.asarray(x, dtype=np.float64)
        s = np.asarray(fixed["strength"], dtype=np.float64)[: x.shape[-2], : x.shape[-1]]
        return np.log(np.abs(1.0 - 2.0 * s * x))
