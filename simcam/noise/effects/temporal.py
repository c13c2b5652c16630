"""Per-frame random effects: ``row_noise``, ``heavy_tail_read``, ``periodic_pattern``, ``frame_flicker``.

Units: normalised raw for offsets, dimensionless for gains.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Effect, per_block, register_effect


@register_effect
class RowNoise(Effect):
    """Per-frame, per-row offset ~ N(0, sigma^2) (normalised raw): horizontal banding."""

    type: Literal["row_noise"] = "row_noise"
    sigma: float = Field(ge=0)

    def frame(self, shape, rng):
        return {"row": (self.sigma * rng.standard_normal(shape[0])).astype(np.float32)}

    def apply(self, x, ctx):
        x += ctx.frame["row"][: x.shape[0], None]
        return x


def tukey_lambda_ppf(u: np.ndarray, lam: float) -> np.ndarray:
    """Quantile of the standard Tukey-lambda law: ``(u^lam - (1-u)^lam) / lam``, logistic at lam = 0.

    Reference: Joiner & Rosenblatt (1971), doi:10.1080/01621459.1971.10482270.
    """
    u = np.asarray(u, dtype=np.float64)
    if lam == 0:
        return np.log(u) - np.log1p(-u)
    return (u**lam - (1.0 - u) ** lam) / lam


@register_effect
class HeavyTailRead(Effect):
    """Heavy-tailed read noise: per-pixel, per-frame ``scale * TukeyLambda(lam)`` added.

    ``lam`` is the Tukey-lambda shape (< 0.14 heavier tails than Gaussian,
    ~0.14 near-Gaussian, 0 logistic; Wei et al. 2020 "A physics-based noise
    formation model", doi:10.1109/CVPR42600.2020.00283, fit lam around -0.2..0.1
    on read noise); ``scale`` in normalised raw.
    """

    type: Literal["heavy_tail_read"] = "heavy_tail_read"
    lam: float = Field(ge=-0.5, le=1.0)
    scale: float = Field(ge=0)

    def apply(self, x, ctx):
        def one(rows, rng):
            u = rng.random(rows.shape)
            u = np.clip(u, 1e-300, None)  # (0, 1)
            rows += (self.scale * tukey_lambda_ppf(u, self.lam)).astype(np.float32)

        if ctx.read is None:
            per_block(x, ctx, one)
            return x
        before = x.copy()
        per_block(x, ctx, one)
        ctx.read += x - before  # it is read noise: later read-noise effects (crosstalk) see it
        return x


@register_effect
class PeriodicPattern(Effect):
    """Sinusoidal banding ``amplitude * sin(2 pi (i / period_px + j * cross_frequency) + phase)`` added
    (normalised raw).

    ``axis: rows`` takes ``i`` the row index and ``j`` the column index (horizontal bands, tilted
    when ``cross_frequency`` is not 0), ``columns`` the other way round. ``cross_frequency``
    (cycles per pixel along the other axis) tilts the bands: an interference whose frequency is
    not a multiple of the line rate advances its phase from one row to the next by a fraction of a
    period, so read-out-order interference shows as oblique stripes (EMVA 1288 Release 4.0, sec.
    8: a peak off the axes of the 2-D spectrogram). ``random_phase`` draws the phase per frame
    (uniform), otherwise ``phase`` (radians) is fixed.
    """

    type: Literal["periodic_pattern"] = "periodic_pattern"
    amplitude: float = Field(ge=0)
    period_px: float = Field(gt=0)
    axis: Literal["rows", "columns"] = "rows"
    cross_frequency: float = Field(0.0, ge=-0.5, le=0.5)
    random_phase: bool = True
    phase: float = 0.0

    def role(self):
        return None if self.random_phase else "offset"

    def frame(self, shape, rng):
        return {"phase": float(rng.uniform(0, 2 * np.pi)) if self.random_phase else self.phase}

    def apply(self, x, ctx):
        phase = ctx.frame.get("phase", self.phase) if ctx.frame else self.phase
        h, w = x.shape[-2:]
        n = h if self.axis == "rows" else w
        along = 2 * np.pi * np.arange(n) / self.period_px
        if self.cross_frequency == 0:
            wave = (self.amplitude * np.sin(along + phase)).astype(np.float32)
            x += wave[:, None] if self.axis == "rows" else wave[None, :]
            return x
        cross = 2 * np.pi * self.cross_frequency * np.arange(w if self.axis == "rows" else h)
        grid = along[:, None] + cross[None, :] if self.axis == "rows" else cross[:, None] + along[None, :]
        x += (self.amplitude * np.sin(grid + phase)).astype(np.float32)
        return x


@register_effect
class FrameFlicker(Effect):
    """Per-frame illumination gain ``g ~ N(1, sigma^2)`` on the signal (dimensionless ``sigma``)."""

    type: Literal["frame_flicker"] = "frame_flicker"
    sigma: float = Field(ge=0, lt=0.3)
    stage = "signal"

    def frame(self, shape, rng):
        return {"gain": float(max(0.0, 1.0 + self.sigma * rng.standard_normal()))}

    def apply(self, x, ctx):
        x *= np.float32(ctx.frame["gain"])
        return x


@register_effect
class Rtn(Effect):
    """Random telegraph noise: a fixed set of pixels switching between two levels from frame to frame.

    A charge trap near the source follower captures and releases an electron at random, so
    the pixel's output jumps between a low and a high level (Janesick, *Photon Transfer*, 2007,
    ch. 10; in CMOS image sensors the main source of heavy read-noise tails). A share
    ``fraction`` of the pixels (drawn once per sensor) each have an amplitude
    ``amplitude * exp(s n_i - s^2 / 2)`` (log-normal with mean ``amplitude``, n_i ~ N(0, 1)); in
    every frame each sits in its high state with probability ``p_high``, independently.

    Parameters
    ----------
    fraction : float
        Share of RTN pixels.
    amplitude : float
        Mean step between the two levels, normalised raw.
    amplitude_log_sigma : float
        Log-normal spread of the steps (0: all equal).
    p_high : float
        Probability of the high state in a frame.
    """

    type: Literal["rtn"] = "rtn"
    fraction: float = Field(ge=0, le=1)
    amplitude: float = Field(ge=0)
    amplitude_log_sigma: float = Field(0.0, ge=0)
    p_high: float = Field(0.5, ge=0, le=1)

    def fixed(self, shape, rng):
        idx = np.flatnonzero(rng.random(shape) < self.fraction)
        s = float(self.amplitude_log_sigma)
        amp = self.amplitude * np.exp(s * rng.standard_normal(idx.size) - s * s / 2) if s > 0 else \
            np.full(idx.size, self.amplitude)
        return {"index": idx, "amplitude": amp.astype(np.float32)}

    def apply(self, x, ctx):
        idx = ctx.fixed["index"]
        if idx.size == 0:
            return x
        high = ctx.block_rng(0).random(idx.size) < self.p_high  # this effect's own stream, one draw per frame
        flat = x.reshape(-1)
        flat[idx] += np.where(high, ctx.fixed["amplitude"], np.float32(0.0))
        return x
