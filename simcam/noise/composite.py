"""``composite``: a base model plus an ordered list of physical effects.

Order of operations for one frame:

1. ``signal = clean``; every ``stage == "signal"`` effect, in list order,
   transforms the expected signal (PRNU, channel gain, flicker, nonlinearity);
2. ``x = base.sample(signal)`` (base model, frame key stream 0);
3. every ``stage == "readout"`` effect, in list order, transforms ``x``.

Fixed patterns are drawn from ``sensor_seed`` (the same for every frame of one
sensor and shape); per-frame draws from the frame key, so one ``rng`` per frame
gives new temporal noise over a persistent fixed pattern.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from ..errors import NoiseModelError
from .base import NoiseCondition, NoiseModel, check_clean, check_same_shape, frame_key, model_from_entry, register_model
from .effects.base import EffectContext, effect_from_entry


@register_model
class Composite(NoiseModel):
    """Base model + effects (see module docstring).

    Parameters
    ----------
    base : model entry
        Any registered model except ``composite``.
    effects : list of effect entries
        Applied in order within their stage.
    sensor_seed : int
        Seed of the fixed patterns (a stage or caller may override it).
    """

    type: Literal["composite"] = "composite"
    base: Any
    effects: list[Any] = Field(default_factory=list)
    sensor_seed: int = Field(0, ge=0)

    @field_validator("base", mode="before")
    @classmethod
    def _base(cls, v):
        m = model_from_entry(v, where="base")
        if isinstance(m, Composite):
            raise ValueError("base: a composite cannot wrap another composite")
        return m

    @field_validator("effects", mode="before")
    @classmethod
    def _effects(cls, v):
        if not isinstance(v, list):
            raise ValueError(f"effects must be a list, got {v!r}")
        return [effect_from_entry(e, where=f"effects[{i}]") for i, e in enumerate(v)]

    def to_entry(self) -> dict[str, Any]:
        return {"type": self.type, "base": self.base.to_entry(), "effects": [e.to_entry() for e in self.effects],
                "sensor_seed": self.sensor_seed}

    def with_sensor_seed(self, seed: int) -> "Composite":
        return self.model_copy(update={"sensor_seed": int(seed)})

    def check_cond(self, cond, shape):
        self.base.check_cond(cond, shape)

    # -- fixed patterns --------------------------------------------------------
    def fixed_patterns(self, shape: tuple[int, int]) -> list[dict[str, Any]]:
        """The fixed-pattern draw of every effect for frames of ``shape``."""
        out, seen = [], {}
        for e in self.effects:
            occ = seen.get(e.type, 0)
            seen[e.type] = occ + 1
            rng = np.random.default_rng(np.random.SeedSequence([self.sensor_seed, e.sensor_stream(), occ]))
            out.append(e.fixed(tuple(shape), rng))
        return out

    # -- sampling ----------------------------------------------------------------
    def sample(self, clean, cond: NoiseCondition, rng: np.random.Generator, *, chunk_rows: int | None = None,
               threads: int = 1):
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self.check_cond(cond, clean.shape)
        key = frame_key(rng)
        fixed = self.fixed_patterns(clean.shape)
        frames = []
        for i, e in enumerate(self.effects):
            frames.append(e.frame(clean.shape, np.random.default_rng(np.random.SeedSequence([int(k) for k in key] + [1000 + i]))))
        signal = clean.copy()
        for i, e in enumerate(self.effects):
            if e.stage == "signal":
                signal = e.apply(signal, self._ctx(cond, key, i, fixed, frames, None))
        x = np.empty(clean.shape, dtype=np.float32)
        h = clean.shape[0]
        from .base import BLOCK_ROWS

        step = h if not chunk_rows else max(BLOCK_ROWS, -(-int(chunk_rows) // BLOCK_ROWS) * BLOCK_ROWS)
        for r0 in range(0, h, step):
            self.base.sample_rows(signal[r0:r0 + step], cond, key, r0, out=x[r0:r0 + step], threads=threads)
        for i, e in enumerate(self.effects):
            if e.stage == "readout":
                x = e.apply(x, self._ctx(cond, key, i, fixed, frames, signal))
        return x

    def sample_rows(self, clean_rows, cond, key, row0, *, out=None, threads=1):
        raise NoiseModelError("model 'composite': sample_rows is not available (effects such as spatial_correlation "
                              "and row_noise act on the whole frame); call sample() (chunk_rows still applies to the base model)")

    def _ctx(self, cond, key, i, fixed, frames, signal):
        return EffectContext(cfa=cond.cfa, key=key, stream=1 + i, fixed=fixed[i], frame=frames[i] if frames else {},
                             signal=signal)

    # -- likelihood -------------------------------------------------------------
    def log_prob(self, noisy, clean, cond: NoiseCondition) -> np.ndarray:
        """log-likelihood given the fixed pattern of ``sensor_seed``.

        Tractable when every effect is a deterministic signal transform or an
        additive offset (PRNU, channel gain, nonlinearity, DSNU, column FPN,
        black-level offset, fixed-phase periodic pattern); otherwise raises.
        """
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        x = check_same_shape(noisy, clean).astype(np.float32)
        bad = [e.type for e in self.effects if e.role() is None]
        if bad:
            raise NoiseModelError(f"model 'composite': log_prob is not tractable with effect(s) {bad} (random per frame or discretising)")
        fixed = self.fixed_patterns(clean.shape)
        signal = clean.copy()
        offset = np.zeros(clean.shape, dtype=np.float32)
        for i, e in enumerate(self.effects):
            ctx = EffectContext(cfa=cond.cfa, key=None, stream=1 + i, fixed=fixed[i], frame={}, signal=signal)
            if e.role() == "signal":
                signal = e.apply(signal, ctx)
            else:
                offset = e.apply(offset, ctx)
        return self.base.log_prob(x.astype(np.float64) - offset, signal, cond)

    def variance(self, clean, cond):
        if self.effects:
            raise NoiseModelError("model 'composite': no closed-form variance with effects; use the base model's")
        return self.base.variance(clean, cond)
