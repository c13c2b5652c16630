"""``hot_pixels``: a fixed set of defective pixels (hot, stuck, dead), drawn from the sensor seed."""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np
from pydantic import Field, model_validator

from .base import Effect, register_effect
from .dark import exposure_of


@register_effect
class HotPixels(Effect):
    """Defective pixels, disjoint fixed sets drawn per sensor.

    Parameters
    ----------
    hot_fraction : float
        Fraction of pixels with an extra dark signal ``hot_offset`` (normalised raw) added.
    hot_offset : float
        The hot pixels' extra signal, normalised raw (e.g. 0.05); with ``hot_log_sigma > 0``
        the *mean* of their log-normal offsets.
    hot_log_sigma : float
        Spread of the hot pixels' offsets, >= 0 (natural-log units, dimensionless). 0 (default):
        every hot pixel gets ``hot_offset``. Otherwise pixel i gets
        ``hot_offset * exp(hot_log_sigma * n_i - hot_log_sigma**2 / 2)``, n_i ~ N(0, 1) drawn once
        per sensor: a log-normal with mean ``hot_offset`` and coefficient of variation
        ``sqrt(exp(hot_log_sigma**2) - 1)`` (dark-current outliers are roughly log-normal; EMVA 1288
        sec. 8.3 shows their spread in the dark-signal histogram).
    stuck_fraction : float
        Fraction of pixels that always read ``stuck_value``.
    stuck_value : float
        Their value, normalised raw (1.0 = saturated).
    dead_fraction : float
        Fraction of pixels that always read 0.
    hot_electron : float, optional
        Normalised raw per electron (``K / (white - black)``). With it the hot pixels' extra signal
        is dark *charge*: each frame adds ``hot_electron * Poisson(offset / hot_electron)`` (same
        mean, plus its shot noise, as dark electrons carry: EMVA 1288 R4.0 sec. 4.2; A. Abdelhamed,
        *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2).
        None (default): a fixed offset, no temporal noise of its own.
    hot_rate : float
        Mean extra dark signal per second of exposure of a hot pixel (normalised raw / s, >= 0): a hot
        pixel is a local dark current, so its signal grows with the exposure time t, ``offset_i +
        rate_i t`` (EMVA 1288 R4.0 sec. 4.2 and 8.5: defect pixels are seen in the dark image at long
        exposures). 0 (default): the offset alone, no exposure time needed. Otherwise the noise stage
        needs the frame's exposure time, as for ``dark_current``.
    hot_rate_log_sigma : float
        Spread of the rates over the hot pixels, as ``hot_log_sigma`` for the offsets (a log-normal of
        mean ``hot_rate``), drawn independently of the offsets.
    """

    type: Literal["hot_pixels"] = "hot_pixels"
    hot_fraction: float = Field(0.0, ge=0, le=1)
    hot_offset: float = 0.05
    hot_log_sigma: float = Field(0.0, ge=0)
    hot_electron: Optional[float] = Field(None, gt=0)
    stuck_fraction: float = Field(0.0, ge=0, le=1)
    stuck_value: float = 1.0
    dead_fraction: float = Field(0.0, ge=0, le=1)
    hot_rate: float = Field(0.0, ge=0)
    hot_rate_log_sigma: float = Field(0.0, ge=0)

    @model_validator(mode="after")
    def _sum(self):
        if self.hot_fraction + self.stuck_fraction + self.dead_fraction > 1:
            raise ValueError("hot_fraction + stuck_fraction + dead_fraction must be <= 1")
        return self

    def to_entry(self):
        out = super().to_entry()
        if self.hot_electron is None:  # off: the entry as before the option existed
            out.pop("hot_electron")
        if self.hot_rate == 0:  # no exposure dependence: the entry as before the option existed
            out.pop("hot_rate")
            out.pop("hot_rate_log_sigma")
        return out

    def fixed(self, shape, rng):
        u = rng.random(shape)
        dead = u < self.dead_fraction
        stuck = (u >= self.dead_fraction) & (u < self.dead_fraction + self.stuck_fraction)
        t = self.dead_fraction + self.stuck_fraction
        hot = (u >= t) & (u < t + self.hot_fraction)
        hot_idx = np.flatnonzero(hot)
        out = {"hot": hot_idx, "stuck": np.flatnonzero(stuck), "dead": np.flatnonzero(dead)}
        if self.hot_log_sigma > 0:  # drawn after the map, so the map is the same as with a constant offset
            s = float(self.hot_log_sigma)
            n = rng.standard_normal(hot_idx.size)
            out["hot_offset"] = (self.hot_offset * np.exp(s * n - s * s / 2)).astype(np.float32)
        if self.hot_rate > 0:  # drawn last: the map and offsets are those of the same profile without rates
            s = float(self.hot_rate_log_sigma)
            n = rng.standard_normal(hot_idx.size)
            out["hot_rate"] = (self.hot_rate * np.exp(s * n - s * s / 2)).astype(np.float32)
        return out

    def apply(self, x, ctx):
        flat = x.reshape(-1)
        off = ctx.fixed.get("hot_offset", np.float32(self.hot_offset))
        if self.hot_rate > 0:
            off = (off + ctx.fixed["hot_rate"] * np.float32(exposure_of(ctx, self.type))).astype(np.float32)
        if self.hot_electron is None:
            flat[ctx.fixed["hot"]] += off
        elif ctx.fixed["hot"].size:  # dark charge: Poisson electrons, one draw per frame (whole frame, block 0)
            e = float(self.hot_electron)
            lam = np.broadcast_to(np.asarray(off, dtype=np.float64) / e, ctx.fixed["hot"].shape)
            flat[ctx.fixed["hot"]] += (np.float32(e) * ctx.block_rng(0).poisson(lam)).astype(np.float32)
        flat[ctx.fixed["stuck"]] = np.float32(self.stuck_value)
        flat[ctx.fixed["dead"]] = np.float32(0.0)
        return x


@register_effect
class DeadPixels(Effect):
    """Dead and stuck pixels: fixed defects that read black (dead) or a fixed value (stuck) whatever the light.

    Unlike ``hot_pixels`` (an extra dark signal that still responds to light) these pixels
    carry no image information (A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
    dissertation, York University, 2020, ch. 2, defective pixels; EMVA 1288 R4.0 sec. 8.5, defect
    pixels). The set is drawn once per sensor.

    A dead pixel has no photo-response: it reads black. With ``dead_read_noise`` its read-out chain
    still works (a broken photodiode behind a working amplifier), so it reads black plus the read
    noise of the frame; without, it reads exactly black (a dead read-out). A stuck pixel reads the
    same value in every frame (a shorted node).

    Parameters
    ----------
    dead_fraction : float
        Share of pixels that read 0 (black).
    stuck_fraction : float
        Share of pixels that read ``stuck_value``.
    stuck_value : float
        Normalised raw (1.0: white, saturated).
    stuck_values : list of float, optional
        Levels the stuck pixels read (normalised raw), e.g. a sensor's measured ones: each stuck
        pixel reads one of them, drawn once per sensor (uniformly); replaces ``stuck_value``. Stuck
        pixels of one sensor often sit at several levels: white, black, zero (a node shorted to
        either rail, or held at a leakage level).
    dead_read_noise : bool
        Dead pixels keep the frame's read noise (default False: exactly black).
    """

    type: Literal["dead_pixels"] = "dead_pixels"
    dead_fraction: float = Field(0.0, ge=0, le=1)
    stuck_fraction: float = Field(0.0, ge=0, le=1)
    stuck_value: float = 1.0
    stuck_values: list[float] | None = Field(None, min_length=1)
    dead_read_noise: bool = False

    def to_entry(self):
        out = super().to_entry()
        if self.stuck_values is None:  # one level: the entry as before the option existed
            out.pop("stuck_values", None)
        return out

    @property
    def needs_read(self) -> bool:  # the read noise is sampled apart only when dead pixels keep it
        return bool(self.dead_read_noise and self.dead_fraction > 0)

    @model_validator(mode="after")
    def _sum(self):
        if self.dead_fraction + self.stuck_fraction > 1:
            raise ValueError("dead_fraction + stuck_fraction must be <= 1")
        return self

    def fixed(self, shape, rng):
        u = rng.random(shape)
        dead = u < self.dead_fraction
        stuck = (u >= self.dead_fraction) & (u < self.dead_fraction + self.stuck_fraction)
        out = {"dead": np.flatnonzero(dead), "stuck": np.flatnonzero(stuck)}
        if self.stuck_values is not None:  # drawn after the map: the map is that of one level
            levels = np.asarray(self.stuck_values, np.float32)
            out["stuck_value"] = levels[rng.integers(levels.size, size=out["stuck"].size)]
        return out

    def apply(self, x, ctx):
        flat = x.reshape(-1)
        dead = ctx.fixed["dead"]
        if self.dead_read_noise and ctx.read is not None:
            flat[dead] = ctx.read.reshape(-1)[dead]
        else:
            flat[dead] = np.float32(0.0)
        flat[ctx.fixed["stuck"]] = ctx.fixed.get("stuck_value", np.float32(self.stuck_value))
        return x
