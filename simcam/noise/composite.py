"""``composite``: a base model plus an ordered list of physical effects.

Order of operations for one frame:

1. ``signal = clean``; every ``stage == "signal"`` effect, in list order,
   transforms the expected signal (PRNU, channel gain, flicker);
2. ``x = base.sample(signal)`` (base model, frame key stream 0);
3. every ``stage == "readout"`` effect, in list order, transforms ``x``
   (crosstalk, read-noise effects, the sensor/ADC response ``nonlinearity``,
   offsets, defects, quantization: list them in signal-chain order).

:meth:`Composite.sample_frames` draws several frames of one sensor at once
(fixed patterns drawn once, base model in one kernel pass) for Monte-Carlo use.

Fixed patterns are drawn from ``sensor_seed`` (the same for every frame of one
sensor and shape); per-frame draws from the frame key, so one ``rng`` per frame
gives new temporal noise over a persistent fixed pattern.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, PrivateAttr, field_validator

from ..errors import NoiseModelError
from .base import (NoiseCondition, NoiseModel, block_rng, check_clean, check_same_shape, frame_key, register_model, site_map,
                   wrapped_base)
from .kernels.vectorised import normal_f32
from .effects.base import Effect, EffectContext, effect_from_entry

#: block-stream id of the read noise sampled apart (effects use 1 + their index).
READ_STREAM = 1_000_000


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
    #: fixed-pattern draws by frame shape (they depend only on sensor_seed, effects and shape).
    _fixed_cache: dict = PrivateAttr(default_factory=dict)

    @field_validator("base", mode="before")
    @classmethod
    def _base(cls, v):
        return wrapped_base(v, Composite, "base: a composite cannot wrap another composite")

    @field_validator("effects", mode="before")
    @classmethod
    def _effects(cls, v):
        if not isinstance(v, list):
            raise ValueError(f"effects must be a list, got {v!r}")
        return [effect_from_entry(e, where=f"effects[{i}]") for i, e in enumerate(v)]

    def to_entry(self) -> dict[str, Any]:
        return {"type": self.type, "base": self.base.to_entry(), "effects": [e.to_entry() for e in self.effects],
                "sensor_seed": self.sensor_seed}

    def model_copy(self, *, update=None, deep: bool = False) -> "Composite":
        m = super().model_copy(update=update, deep=deep)
        m._fixed_cache = {}  # the copy may have other effects or another sensor seed
        return m

    def with_sensor_seed(self, seed: int) -> "Composite":
        return self.model_copy(update={"sensor_seed": int(seed)})

    def check_cond(self, cond, shape):
        self.base.check_cond(cond, shape)

    # -- fixed patterns --------------------------------------------------------
    def fixed_patterns(self, shape: tuple[int, int]) -> list[dict[str, Any]]:
        """The fixed-pattern draw of every effect for frames of ``shape`` (cached per shape; read-only)."""
        shape = tuple(int(v) for v in shape)
        hit = self._fixed_cache.get(shape)
        if hit is None:
            if len(self._fixed_cache) >= 4:
                self._fixed_cache.clear()
            hit = self._fixed_cache[shape] = self._draw_fixed(shape)
        return hit

    def _draw_fixed(self, shape: tuple[int, int]) -> list[dict[str, Any]]:
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
        base, read_var = self._base_parts(cond)
        x = np.empty(clean.shape, dtype=np.float32)
        h = clean.shape[0]
        from .base import BLOCK_ROWS

        step = h if not chunk_rows else max(BLOCK_ROWS, -(-int(chunk_rows) // BLOCK_ROWS) * BLOCK_ROWS)
        for r0 in range(0, h, step):
            base.sample_rows(signal[r0:r0 + step], cond, key, r0, out=x[r0:r0 + step], threads=threads)
        read = None
        if read_var is not None:  # the read noise apart, row block by row block (tiling-invariant)
            read = np.empty(clean.shape, dtype=np.float32)
            for r in range(0, h, BLOCK_ROWS):
                rows = read[r:r + BLOCK_ROWS]
                normal_f32(block_rng(key, r // BLOCK_ROWS, stream=READ_STREAM), rows.size, out=rows)
                rows *= np.sqrt(site_map(read_var, rows.shape, r, name="read variance"))
            x += read
        for i, e in enumerate(self.effects):
            if e.stage == "readout":
                x = e.apply(x, self._ctx(cond, key, i, fixed, frames, signal, read))
        return x

    def _base_parts(self, cond):
        """(model sampled by the base pass, read-noise variance sampled apart or None)."""
        if not any(e.needs_read for e in self.effects):
            return self.base, None
        split = self.base.read_split()
        if split is None:
            names = [e.type for e in self.effects if e.needs_read]
            raise NoiseModelError(f"{cond.source or 'composite'}: effects {names} act on the read noise but base model "
                                  f"{self.base.type!r} has no separate read-noise part (use poisson_gaussian, nlf or gaussian)")
        return split

    def sample_frames(self, clean, cond: NoiseCondition, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` independent noisy frames (float32, n x H x W) of one sensor for the same ``clean``.

        For Monte-Carlo use (the calibration loop's parametric bootstrap): the
        fixed patterns are drawn once (cached per shape), every frame gets its
        own frame key for the per-frame effects, and the base model samples all
        frames in one kernel pass (:meth:`NoiseModel.sample_stack`). Same law as
        ``n`` calls of :meth:`sample`, deterministic given ``rng``, but not the
        same bytes (one stream for the base noise of the stack).
        """
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self.check_cond(cond, clean.shape)
        n = int(n)
        shape = clean.shape
        fixed = self.fixed_patterns(shape)
        keys = [frame_key(rng) for _ in range(n)]
        # per-frame draws (row offsets, flicker gain, phase) straight from rng: no generator per frame
        per_frame = [type(e).frame is not Effect.frame for e in self.effects]
        draws = [[e.frame(shape, rng) if per_frame[i] else {} for i, e in enumerate(self.effects)] for _ in keys]
        signal = np.empty((n,) + shape, dtype=np.float32)
        sig_effects = [(i, e) for i, e in enumerate(self.effects) if e.stage == "signal"]
        for f in range(n):
            s = clean.copy()
            for i, e in sig_effects:
                s = e.apply(s, self._ctx(cond, keys[f], i, fixed, draws[f], None))
            signal[f] = s
        base, read_var = self._base_parts(cond)
        x = base.sample_stack(signal, cond, rng)
        read = None
        if read_var is not None:
            read = normal_f32(rng, x.size).reshape(x.shape)
            read *= np.sqrt(site_map(read_var, shape, 0, name="read variance"))
            x += read
        for i, e in enumerate(self.effects):  # effect by effect (each frame sees them in list order)
            if e.stage != "readout":
                continue
            if e.stack_ok:
                x = e.apply(x, self._ctx(cond, None, i, fixed, None, signal, read))
                continue
            for f in range(n):
                x[f] = e.apply(x[f], self._ctx(cond, keys[f], i, fixed, draws[f], signal[f],
                                               None if read is None else read[f]))
        return x

    def sample_rows(self, clean_rows, cond, key, row0, *, out=None, threads=1):
        raise NoiseModelError("model 'composite': sample_rows is not available (effects such as spatial_correlation "
                              "and row_noise act on the whole frame); call sample() (chunk_rows still applies to the base model)")

    def _ctx(self, cond, key, i, fixed, frames, signal, read=None):
        return EffectContext(cfa=cond.cfa, key=key, stream=1 + i, fixed=fixed[i], frame=frames[i] if frames else {},
                             signal=signal, read=read, exposure_s=cond.exposure_s)

    # -- likelihood -------------------------------------------------------------
    def log_prob(self, noisy, clean, cond: NoiseCondition) -> np.ndarray:
        """log-likelihood given the fixed pattern of ``sensor_seed``.

        Tractable when every effect is a deterministic signal transform (PRNU,
        channel gain), an additive offset (DSNU, column FPN, black-level offset,
        fixed-phase periodic pattern) or a monotonic response (nonlinearity: the
        readout effects are undone in reverse order on the observation and
        ``log |f'|`` is subtracted, change of variables); otherwise raises.
        """
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        y = check_same_shape(noisy, clean).astype(np.float32).astype(np.float64)
        bad = [e.type for e in self.effects if e.role() is None]
        if bad:
            raise NoiseModelError(f"model 'composite': log_prob is not tractable with effect(s) {bad} "
                                  "(random per frame or discretising)")
        fixed = self.fixed_patterns(clean.shape)
        signal = clean.copy()
        for i, e in enumerate(self.effects):
            if e.stage == "signal":
                signal = e.apply(signal, EffectContext(cfa=cond.cfa, key=None, stream=1 + i, fixed=fixed[i], frame={},
                                                       signal=signal, exposure_s=cond.exposure_s))
        log_jac = np.zeros(clean.shape, dtype=np.float64)
        for i in reversed(range(len(self.effects))):
            e = self.effects[i]
            if e.stage == "signal":
                continue
            if e.role() == "response":
                y = e.inverse(y, fixed[i])
                log_jac += e.log_slope(y, fixed[i])
            else:
                ctx = EffectContext(cfa=cond.cfa, key=None, stream=1 + i, fixed=fixed[i], frame={}, signal=signal,
                                    exposure_s=cond.exposure_s)
                y = y - e.apply(np.zeros(clean.shape, dtype=np.float32), ctx)
        return self.base.log_prob(y, signal, cond) - log_jac

    def variance(self, clean, cond):
        if self.effects:
            raise NoiseModelError("model 'composite': no closed-form variance with effects; use the base model's")
        return self.base.variance(clean, cond)
