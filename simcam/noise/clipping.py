"""``clipped``: a base model followed by clipping to [low, high] (seed eq. 3.9-3.10).

The likelihood is the censored one: inside (low, high) the base density; at
``noisy <= low`` the point mass ``P_base(noisy <= low)``; at ``noisy >= high``
the point mass ``P_base(noisy >= high)``. For Gaussian bases this is the doubly
censored normal of seed eq. 3.10. The mixed measure (Lebesgue on the interior
plus two atoms) is what the per-pixel value is a log-density of.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import field_validator, model_validator

from ..errors import NoiseModelError
from .base import NoiseModel, check_clean, check_same_shape, model_from_entry, register_model


@register_model
class Clipped(NoiseModel):
    """Clip the output of ``base`` to [low, high] (normalised raw; default [0, 1])."""

    type: Literal["clipped"] = "clipped"
    base: Any
    low: float = 0.0
    high: float = 1.0

    @field_validator("base", mode="before")
    @classmethod
    def _base(cls, v):
        m = model_from_entry(v, where="base")
        if isinstance(m, Clipped):
            raise ValueError("base: a clipped model cannot wrap another clipped model")
        return m

    @model_validator(mode="after")
    def _range(self):
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self

    def to_entry(self) -> dict[str, Any]:
        return {"type": self.type, "base": self.base.to_entry(), "low": self.low, "high": self.high}

    def check_cond(self, cond, shape):
        self.base.check_cond(cond, shape)

    def sample_rows(self, clean_rows, cond, key, row0, *, out=None, threads=1):
        out = self.base.sample_rows(clean_rows, cond, key, row0, out=out, threads=threads)
        return np.clip(out, np.float32(self.low), np.float32(self.high), out=out)

    def sample_stack(self, clean, cond, rng):
        out = self.base.sample_stack(clean, cond, rng)
        return np.clip(out, np.float32(self.low), np.float32(self.high), out=out)

    def variance(self, clean, cond):
        raise NoiseModelError("model 'clipped': the censored variance has no closed form here; use the base model's")

    def log_prob(self, noisy, clean, cond):
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        x = check_same_shape(noisy, clean).astype(np.float64)
        if not hasattr(self.base, "cdf"):
            raise NoiseModelError(f"model 'clipped': base {self.base.type!r} has no CDF, the censored likelihood needs one")
        # samples are clipped at the float32 bounds (sample() works in float32): 0.6 is stored as 0.6000000238
        lo32, hi32 = float(np.float32(self.low)), float(np.float32(self.high))
        if (x < min(self.low, lo32)).any() or (x > max(self.high, hi32)).any():
            raise NoiseModelError(
                f"{cond.source or 'noisy'}: expected clipped values in [{self.low}, {self.high}], got range "
                f"[{x.min():.6g}, {x.max():.6g}]")
        out = np.empty(clean.shape, dtype=np.float64)
        at_lo = x <= max(self.low, lo32)
        at_hi = x >= min(self.high, hi32)
        inside = ~(at_lo | at_hi)
        if inside.any():
            out[inside] = self.base.log_prob(x, clean, cond)[inside]
        if at_lo.any():
            out[at_lo] = self.base.cdf(self.low, clean, cond, log=True)[at_lo]
        if at_hi.any():
            out[at_hi] = self.base.cdf(self.high, clean, cond, log=True, upper=True)[at_hi]
        return out
