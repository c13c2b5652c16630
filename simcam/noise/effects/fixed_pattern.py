"""Fixed-pattern effects (drawn once per sensor seed): ``column_fpn``, ``dsnu``, ``prnu``, ``black_level_offset``.

Units: normalised raw (offsets), dimensionless (gains). References: EMVA 1288
release 4.0, sections on DSNU and PRNU (spatial non-uniformities); Abdelhamed 2020, ch. 2.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from ..base import SiteParam, validate_site_param
from .base import Effect, EffectContext, register_effect, site_array


@register_effect
class ColumnFPN(Effect):
    """Fixed per-column offset ~ N(0, sigma^2) (normalised raw), the same in every frame."""

    type: Literal["column_fpn"] = "column_fpn"
    sigma: float = Field(ge=0)
    logprob_role = "offset"

    def fixed(self, shape, rng):
        return {"col": (self.sigma * rng.standard_normal(shape[1])).astype(np.float32)}

    stack_ok = True

    def apply(self, x, ctx):
        x += ctx.fixed["col"][: x.shape[-1]]  # broadcasts over rows (and frames)
        return x


@register_effect
class DSNU(Effect):
    """Dark signal non-uniformity: fixed per-pixel offset ~ N(0, sigma^2) (normalised raw)."""

    type: Literal["dsnu"] = "dsnu"
    sigma: float = Field(ge=0)
    logprob_role = "offset"
    stack_ok = True

    def fixed(self, shape, rng):
        return {"offset": (self.sigma * rng.standard_normal(shape)).astype(np.float32)}

    def apply(self, x, ctx):
        x += ctx.fixed["offset"]
        return x


@register_effect
class PRNU(Effect):
    """Photo-response non-uniformity: fixed per-pixel gain ``1 + sigma * N(0, 1)`` on the signal.

    ``sigma`` is the relative gain spread (dimensionless, e.g. 0.01 = 1 %), the
    PRNU1288 of EMVA 1288.
    """

    type: Literal["prnu"] = "prnu"
    sigma: float = Field(ge=0, lt=0.2)
    stage = "signal"
    logprob_role = "signal"

    def fixed(self, shape, rng):
        return {"gain": (1.0 + self.sigma * rng.standard_normal(shape)).astype(np.float32)}

    def apply(self, x, ctx):
        x *= ctx.fixed["gain"]
        np.maximum(x, 0, out=x)  # an expected signal cannot go negative (gain > 0 except at > 5 sigma)
        return x


@register_effect
class BlackLevelOffset(Effect):
    """A constant offset per CFA site (normalised raw): residual black-level error."""

    type: Literal["black_level_offset"] = "black_level_offset"
    offset: SiteParam
    logprob_role = "offset"

    @field_validator("offset")
    @classmethod
    def _chk(cls, v):
        return validate_site_param(v, "offset", minimum=None)

    stack_ok = True

    def apply(self, x, ctx: EffectContext):
        x += site_array(self.offset, x.shape[-2:], name="offset")  # broadcasts over frames
        return x
