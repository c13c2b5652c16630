"""Exposure-dependent dark signal: ``dark_current`` (thermal electrons) and ``amp_glow``.

Both add *electrons* that accumulate during the exposure, so both need the exposure time
(``NoiseCondition.exposure_s``: the noise stage takes it from the frame's ExposureTime, and
``simcam synth --exposure`` sets it). The electrons are Poisson: their shot noise is part of
the effect, as in EMVA 1288 R4.0 sec. 4.2 (the dark signal ``mu_d = mu_d0 + mu_therm`` with
``mu_therm`` proportional to the exposure time, and its variance ``sigma_d^2 = sigma_d0^2 +
sigma_therm^2``, ``sigma_therm^2 = mu_therm`` in electrons). ``electron`` converts electrons to
normalised raw: ``K / (white - black)`` with the system gain K in DN/e- (for an ``nlf`` or
``poisson_gaussian`` base it is that model's ``beta1``).

References: A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York
University, 2020, ch. 2 (dark current: thermally generated electrons, growing with exposure
time and temperature); EMVA Standard 1288 R4.0, sec. 4.2 and 8.4 (dark current: mean and
variance methods; doubling temperature).
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np
from pydantic import Field

from ...errors import NoiseModelError
from ..kernels.poisson import poisson_table_f32
from .base import Effect, EffectContext, per_block, register_effect


def exposure_of(ctx: EffectContext, effect: str) -> float:
    t = ctx.exposure_s
    if t is None or not np.isfinite(t) or t < 0:
        raise NoiseModelError(f"effect {effect!r}: exposure time {t!r}; expected the exposure in seconds "
                              "(the frame's ExposureTime, NoiseCondition(exposure_s=...), or simcam synth --exposure)")
    return float(t)


def _add_poisson_electrons(x: np.ndarray, lam: np.ndarray, electron: float, ctx: EffectContext) -> None:
    """x += electron * Poisson(lam), drawn row block by row block (independent of tiling), by the exact
    table sampler of :mod:`simcam.noise.kernels.poisson` (twice numpy's ``Generator.poisson`` on the
    small means of dark frames)."""
    row = [0]
    e = np.float32(electron)

    def add(rows, rng):
        r0 = row[0]
        n = rows.shape[0]
        rows += e * poisson_table_f32(rng, lam[r0:r0 + n])
        row[0] += n

    per_block(x, ctx, add)


@register_effect
class DarkCurrent(Effect):
    """Thermal dark electrons: per pixel Poisson(rate_i x t), the rate non-uniform (DCNU), temperature-scaled.

    Parameters
    ----------
    rate : float
        Mean dark current over the pixels, electrons per second (at ``reference_temperature_c``).
    dcnu_log_sigma : float
        Dark-current non-uniformity: pixel *i* has rate ``rate * exp(s n_i - s^2 / 2)``,
        n_i ~ N(0, 1) drawn once per sensor (a log-normal with mean ``rate``; coefficient of
        variation ``sqrt(exp(s^2) - 1)``). 0: uniform.
    electron : float
        Normalised raw per electron (``K / (white - black)``).
    temperature_c, reference_temperature_c, doubling_c : float, optional
        With all three, the rate is scaled by ``2 ** ((temperature_c - reference_temperature_c) /
        doubling_c)`` (EMVA 1288 R4.0 sec. 8.4: dark current doubles every ``doubling_c`` kelvin,
        typically 6-8 K).
    """

    type: Literal["dark_current"] = "dark_current"
    rate: float = Field(ge=0)
    dcnu_log_sigma: float = Field(0.0, ge=0)
    electron: float = Field(gt=0)
    temperature_c: Optional[float] = None
    reference_temperature_c: float = 25.0
    doubling_c: Optional[float] = Field(None, gt=0)

    def scale(self) -> float:
        if self.temperature_c is None or self.doubling_c is None:
            return 1.0
        return float(2.0 ** ((self.temperature_c - self.reference_temperature_c) / self.doubling_c))

    def fixed(self, shape, rng):
        if self.dcnu_log_sigma == 0:
            return {}
        s = float(self.dcnu_log_sigma)
        return {"rate": np.exp(s * rng.standard_normal(shape) - s * s / 2)}

    def rate_map(self, shape, ctx: EffectContext) -> np.ndarray:
        """Electrons per second of every pixel (the expected dark current)."""
        m = ctx.fixed.get("rate")
        base = self.rate * self.scale()
        return np.full(shape, base) if m is None else base * m[: shape[0], : shape[1]]

    def apply(self, x, ctx):
        t = exposure_of(ctx, self.type)
        if self.rate == 0 or t == 0:
            return x
        _add_poisson_electrons(x, self.rate_map(x.shape, ctx) * t, self.electron, ctx)
        return x


@register_effect
class AmpGlow(Effect):
    """Amplifier glow: a dark signal proportional to the exposure, rising towards a corner or an edge.

    The read-out amplifier emits light (or heat) while the sensor integrates: the dark frame
    brightens smoothly towards the amplifier. Pixel (y, x) collects Poisson electrons with mean
    ``rate * t * exp(-d(y, x) / (scale * L))``, d its distance to ``origin`` (a corner or an edge)
    and L the frame's diagonal (corner) or its extent across the edge.

    Parameters
    ----------
    rate : float
        Electrons per second at the origin.
    origin : str
        ``top_left``, ``top_right``, ``bottom_left``, ``bottom_right``, ``top``, ``bottom``, ``left``, ``right``.
    scale : float
        Fall-off length as a share of L (e.g. 0.1: 1/e at a tenth of the way).
    electron : float
        Normalised raw per electron.
    """

    type: Literal["amp_glow"] = "amp_glow"
    rate: float = Field(ge=0)
    origin: Literal["top_left", "top_right", "bottom_left", "bottom_right", "top", "bottom", "left", "right"] = \
        "top_right"
    scale: float = Field(0.1, gt=0)
    electron: float = Field(gt=0)

    def field(self, shape: tuple[int, int]) -> np.ndarray:
        """The glow's relative profile (1 at the origin), float64 (H, W)."""
        h, w = shape
        yy = np.arange(h, dtype=np.float64)[:, None]
        xx = np.arange(w, dtype=np.float64)[None, :]
        dy = yy if "top" in self.origin else (h - 1 - yy)
        dx = xx if "left" in self.origin else (w - 1 - xx)
        if self.origin in ("top", "bottom"):
            d, length = np.broadcast_to(dy, shape), h
        elif self.origin in ("left", "right"):
            d, length = np.broadcast_to(dx, shape), w
        else:
            d, length = np.sqrt(dy * dy + dx * dx), np.hypot(h, w)
        return np.exp(-d / (self.scale * length))

    def apply(self, x, ctx):
        t = exposure_of(ctx, self.type)
        if self.rate == 0 or t == 0:
            return x
        _add_poisson_electrons(x, self.rate * t * self.field(x.shape), self.electron, ctx)
        return x
