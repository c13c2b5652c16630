"""Deterministic response effects: ``channel_gain``, ``nonlinearity``, ``quantization``."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from ..base import SiteParam, site_values, validate_site_param
from .base import Effect, register_effect, site_array


@register_effect
class ChannelGain(Effect):
    """Per-CFA-site gain on the signal (dimensionless, > 0), e.g. a per-channel analog gain error."""

    type: Literal["channel_gain"] = "channel_gain"
    gain: SiteParam
    stage = "signal"
    logprob_role = "signal"

    @field_validator("gain")
    @classmethod
    def _chk(cls, v):
        validate_site_param(v, "gain")
        if (site_values(v, name="gain") <= 0).any():
            raise ValueError(f"gain must be > 0, got {v!r}")
        return v

    def apply(self, x, ctx):
        x *= site_array(self.gain, x.shape, name="gain")
        return x


@register_effect
class Nonlinearity(Effect):
    """Compressive response towards saturation on the signal: ``y = x - strength * x^2``.

    Slope 1 at black, ``1 - strength`` of full scale reached at x = 1 (a 2 %
    compression at white is ``strength: 0.02``). Monotonic for x < 1/(2 strength),
    i.e. beyond 1.1 for every allowed strength (<= 0.45).
    """

    type: Literal["nonlinearity"] = "nonlinearity"
    strength: float = Field(ge=0, le=0.45)
    stage = "signal"
    logprob_role = "signal"

    def apply(self, x, ctx):
        x -= np.float32(self.strength) * x * x
        return x


@register_effect
class Quantization(Effect):
    """ADC quantisation: ``DN = round((x * range_dn + offset_dn) / step_dn) * step_dn``, back to normalised raw.

    ``range_dn`` is white - black in DN, ``offset_dn`` the black level (DN;
    only its fractional part relative to ``step_dn`` matters), ``step_dn`` the
    ADC step in DN (1 for a plain ADC; > 1 models dropped low bits).
    """

    type: Literal["quantization"] = "quantization"
    range_dn: float = Field(gt=0)
    step_dn: float = Field(1.0, gt=0)
    offset_dn: float = 0.0

    def apply(self, x, ctx):
        s = np.float64(self.step_dn)
        dn = np.round((x.astype(np.float64) * self.range_dn + self.offset_dn) / s) * s
        return ((dn - self.offset_dn) / self.range_dn).astype(np.float32)
