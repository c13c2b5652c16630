"""``hot_pixels``: a fixed set of defective pixels (hot, stuck, dead), drawn from the sensor seed."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from .base import Effect, register_effect


@register_effect
class HotPixels(Effect):
    """Defective pixels, disjoint fixed sets drawn per sensor.

    Parameters
    ----------
    hot_fraction : float
        Fraction of pixels with an extra dark signal ``hot_offset`` (normalised raw) added.
    hot_offset : float
        The hot pixels' extra signal, normalised raw (e.g. 0.05).
    stuck_fraction : float
        Fraction of pixels that always read ``stuck_value``.
    stuck_value : float
        Their value, normalised raw (1.0 = saturated).
    dead_fraction : float
        Fraction of pixels that always read 0.
    """

    type: Literal["hot_pixels"] = "hot_pixels"
    hot_fraction: float = Field(0.0, ge=0, le=1)
    hot_offset: float = 0.05
    stuck_fraction: float = Field(0.0, ge=0, le=1)
    stuck_value: float = 1.0
    dead_fraction: float = Field(0.0, ge=0, le=1)

    @model_validator(mode="after")
    def _sum(self):
        if self.hot_fraction + self.stuck_fraction + self.dead_fraction > 1:
            raise ValueError("hot_fraction + stuck_fraction + dead_fraction must be <= 1")
        return self

    def fixed(self, shape, rng):
        u = rng.random(shape)
        dead = u < self.dead_fraction
        stuck = (u >= self.dead_fraction) & (u < self.dead_fraction + self.stuck_fraction)
        t = self.dead_fraction + self.stuck_fraction
        hot = (u >= t) & (u < t + self.hot_fraction)
        return {"hot": np.flatnonzero(hot), "stuck": np.flatnonzero(stuck), "dead": np.flatnonzero(dead)}

    def apply(self, x, ctx):
        flat = x.reshape(-1)
        flat[ctx.fixed["hot"]] += np.float32(self.hot_offset)
        flat[ctx.fixed["stuck"]] = np.float32(self.stuck_value)
        flat[ctx.fixed["dead"]] = np.float32(0.0)
        return x
