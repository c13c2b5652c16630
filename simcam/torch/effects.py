"""The composite model's effects on mosaic tensors ``[G, 1, H, W]`` (same laws as :mod:`simcam.noise.effects`).

Fixed patterns (``column_fpn``, ``dsnu``, ``prnu``, ``hot_pixels``) are the
numpy model's own draws (:meth:`simcam.noise.composite.Composite.fixed_patterns`,
from the profile's ``sensor_seed``), computed once per model and frame shape on
the host and kept on the device: the torch composite adds the *same* fixed
pattern as the numpy one. Per-frame draws (row offsets, flicker gain, periodic
phase) and per-pixel ones (heavy-tailed read noise) come from the torch
generator, one per sample.

Each function takes ``(group, x, ctx, state)`` where ``state`` carries the
fixed patterns of the effect (``state.fixed``) and the read noise so far
(``state.read``, a tensor when an effect of the composite acts on the read
noise alone) and returns the new tensor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from .context import Ctx
from .group import Group


@dataclass
class EffectState:
    """Per-effect inputs: ``fixed(name)`` -> stacked fixed-pattern tensor; ``read`` -> read noise or None."""

    fixed: Any
    read: torch.Tensor | None = None
    offsets: np.ndarray | None = None  # per-sample crop offsets [G, 2] in the full frame, or None


# -- signal stage -------------------------------------------------------------

def prnu(group: Group, x, ctx: Ctx, st: EffectState):
    return (x * st.fixed("gain")).clamp_min(0)


def channel_gain(group: Group, x, ctx: Ctx, st: EffectState):
    return x * ctx.site(group, lambda e: e.gain)


def frame_flicker(group: Group, x, ctx: Ctx, st: EffectState):
    sigma = ctx.scalar(group, lambda e: e.sigma, dtype=torch.float64)
    g = (1.0 + sigma * ctx.randn((x.shape[0], 1, 1, 1), dtype=torch.float64)).clamp_min(0)
    return x * g.to(x.dtype)


# -- readout stage ------------------------------------------------------------

def row_noise(group: Group, x, ctx: Ctx, st: EffectState):
    sigma = ctx.scalar(group, lambda e: e.sigma)
    return x + sigma * ctx.randn((x.shape[0], 1, x.shape[-2], 1))


def column_fpn(group: Group, x, ctx: Ctx, st: EffectState):
    return x + st.fixed("col")


def dsnu(group: Group, x, ctx: Ctx, st: EffectState):
    return x + st.fixed("offset")


def black_level_offset(group: Group, x, ctx: Ctx, st: EffectState):
    return x + ctx.site(group, lambda e: e.offset)


def hot_pixels(group: Group, x, ctx: Ctx, st: EffectState):
    return torch.where(st.fixed("set_mask"), st.fixed("set_value"), x + st.fixed("add"))


def tukey_lambda_ppf(u: torch.Tensor, lam: torch.Tensor) -> torch.Tensor:
    """``(u^lam - (1-u)^lam) / lam`` (logistic ``log(u / (1-u))`` where lam = 0); Joiner & Rosenblatt (1971)."""
    safe = torch.where(lam == 0, torch.ones_like(lam), lam)
    t = (u ** safe - (1.0 - u) ** safe) / safe
    return torch.where(lam == 0, torch.log(u) - torch.log1p(-u), t)


def heavy_tail_read(group: Group, x, ctx: Ctx, st: EffectState):
    lam = ctx.scalar(group, lambda e: e.lam, dtype=torch.float64)
    scale = ctx.scalar(group, lambda e: e.scale, dtype=torch.float64)
    # float64 uniforms, as the numpy effect (a float32 grid would cut the heavy tail at 2^-24)
    u = ctx.rand(x.shape, dtype=torch.float64).clamp_min(1e-300)
    add = (scale * tukey_lambda_ppf(u, lam)).to(x.dtype)
    if st.read is not None:
        st.read = st.read + add
    return x + add


def plane_filter(n: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """Variance-preserving separable ``[c, 1, c]`` filter inside each CFA plane (same-colour pixels 2 px apart;
    borders reflected about each plane's edge pixel); ``c`` broadcasts as ``[G, 1, 1, 1]``."""
    out = n
    h, w = n.shape[-2:]
    p = F.pad(out, (0, 0, 2, 2), mode="reflect")
    out = out + c * (p[..., 0:h, :] + p[..., 4:h + 4, :])
    p = F.pad(out, (2, 2, 0, 0), mode="reflect")
    out = out + c * (p[..., :, 0:w] + p[..., :, 4:w + 4])
    return out / (1.0 + 2.0 * c * c)


def spatial_correlation(group: Group, x, ctx: Ctx, st: EffectState):
    cs = group.values(lambda e: e.coefficient)
    if not np.any(cs):
        return x
    c = ctx.scalar(group, lambda e: e.coefficient)
    f = plane_filter(st.read, c)
    x = x + (f - st.read)
    st.read = f
    return x


def periodic_pattern(group: Group, x, ctx: Ctx, st: EffectState):
    g = x.shape[0]
    amp = ctx.scalar(group, lambda e: e.amplitude, dtype=torch.float64).reshape(-1, 1)
    period = ctx.scalar(group, lambda e: e.period_px, dtype=torch.float64).reshape(-1, 1)
    e0 = group.models[0]
    if e0.random_phase:
        phase = ctx.rand((g, 1), dtype=torch.float64) * (2 * math.pi)
    else:
        phase = ctx.scalar(group, lambda e: e.phase, dtype=torch.float64).reshape(-1, 1)
    ax = 0 if e0.axis == "rows" else 1
    n = x.shape[-2 + ax]
    i = torch.arange(n, device=x.device, dtype=torch.float64)[None, :]
    if st.offsets is not None:  # position in the full frame
        i = i + torch.as_tensor(st.offsets[:, ax], dtype=torch.float64, device=x.device)[:, None]
    wave = (amp * torch.sin(2 * math.pi * i / period + phase)).to(x.dtype)  # [G, n]
    return x + (wave[:, None, :, None] if e0.axis == "rows" else wave[:, None, None, :])


def nonlinearity(group: Group, x, ctx: Ctx, st: EffectState):
    s = ctx.scalar(group, lambda e: e.strength)
    return x - s * x * x


def quantization(group: Group, x, ctx: Ctx, st: EffectState):
    """Rounded to the ADC step in DN (float64 arithmetic, round half to even as numpy); no gradient."""
    f = lambda name: ctx.scalar(group, lambda e: getattr(e, name), dtype=torch.float64)  # noqa: E731
    rng, step, off = f("range_dn"), f("step_dn"), f("offset_dn")
    dn = torch.round((x.detach().double() * rng + off) / step) * step
    return ((dn - off) / rng).to(x.dtype)


#: torch implementation of every effect type (the registry test checks this against simcam's effect registry).
EFFECTS = {
    "prnu": prnu, "channel_gain": channel_gain, "frame_flicker": frame_flicker, "row_noise": row_noise,
    "column_fpn": column_fpn, "dsnu": dsnu, "black_level_offset": black_level_offset, "hot_pixels": hot_pixels,
    "heavy_tail_read": heavy_tail_read, "spatial_correlation": spatial_correlation,
    "periodic_pattern": periodic_pattern, "nonlinearity": nonlinearity, "quantization": quantization,
}


def fixed_arrays(effect, fixed: dict[str, Any], shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """Host arrays ``[1, H, W]``-broadcastable of one effect's fixed-pattern draw (numpy model's ``fixed``)."""
    h, w = shape
    if effect.type == "column_fpn":
        return {"col": np.asarray(fixed["col"], np.float64)[:w].reshape(1, 1, w)}
    if effect.type == "dsnu":
        return {"offset": np.asarray(fixed["offset"], np.float64).reshape(1, h, w)}
    if effect.type == "prnu":
        return {"gain": np.asarray(fixed["gain"], np.float64).reshape(1, h, w)}
    if effect.type == "hot_pixels":
        add = np.zeros(h * w, np.float64)
        add[fixed["hot"]] = fixed.get("hot_offset", np.float32(effect.hot_offset))
        mask = np.zeros(h * w, bool)
        val = np.zeros(h * w, np.float64)
        mask[fixed["stuck"]] = True
        val[fixed["stuck"]] = np.float32(effect.stuck_value)
        mask[fixed["dead"]] = True
        return {"add": add.reshape(1, h, w), "set_mask": mask.reshape(1, h, w), "set_value": val.reshape(1, h, w)}
    return {}
