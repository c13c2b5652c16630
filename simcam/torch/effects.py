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
    per_uniq: Any = None  # name -> list of the distinct models' fixed tensors (not spatial: ADC edges)
    exposure_s: torch.Tensor | None = None  # [G, 1, 1, 1] float64 seconds, or None
    signal: torch.Tensor | None = None  # expected signal after the signal-stage effects (read-out effects)


def _exposure(st: EffectState, name: str) -> torch.Tensor:
    if st.exposure_s is None:
        from ..errors import NoiseModelError

        raise NoiseModelError(f"effect {name!r}: exposure_s: expected each sample's exposure time in seconds "
                              f"(add_noise(..., exposure_s=...)), got none")
    return st.exposure_s


def _poisson_electrons(x, lam: torch.Tensor, electron: torch.Tensor, ctx: Ctx):
    """``x + electron * Poisson(lam)`` (lam float64 broadcastable to x)."""
    lam = lam.expand(x.shape[0], 1, *x.shape[-2:]) if lam.shape[-2:] == x.shape[-2:] else lam.expand_as(x)
    k = ctx.poisson(lam.contiguous())
    return x + (electron * k).to(x.dtype)


def _by_model(group: Group, x, fn):
    """``fn(i_uniq, rows)`` applied to the samples of each distinct model (x[rows]); results stitched back."""
    if group.shared:
        return fn(0, x)
    out = torch.empty_like(x)
    for u in range(len(group.uniq)):
        idx = torch.as_tensor(np.flatnonzero(group.inv == u), device=x.device)
        if idx.numel():
            out = out.index_copy(0, idx, fn(u, x.index_select(0, idx)))
    return out


def _interp_quantiles(u: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """``np.interp(u, linspace(0, 1, n), q)`` for uniforms ``u`` (float64)."""
    n = q.numel()
    pos = u * (n - 1)
    i = pos.floor().clamp(0, n - 2).long()
    f = pos - i
    return q[i] + f * (q[i + 1] - q[i])


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
    """Hot pixels add their offset; with ``hot_electron`` the offset is dark charge, drawn each frame as
    ``hot_electron * Poisson(offset / hot_electron)`` (as the numpy effect); stuck and dead pixels are set."""
    add = st.fixed("add")
    if any(e.hot_rate > 0 for e in group.uniq):  # a local dark current: offset + rate * exposure
        add = add.double() + st.fixed("rate").double() * _exposure(st, "hot_pixels")
    if any(getattr(e, "hot_electron", None) is not None for e in group.uniq):
        el = ctx.scalar(group, lambda e: e.hot_electron or 0.0, dtype=torch.float64)
        safe = torch.where(el > 0, el, torch.ones_like(el))
        lam = (add.double() / safe).expand(x.shape[0], *add.shape[1:]).expand_as(x).contiguous()
        drawn = (safe * ctx.poisson(lam)).to(x.dtype)
        add = torch.where(el > 0, drawn, add.to(x.dtype).expand_as(x))
    return torch.where(st.fixed("set_mask"), st.fixed("set_value"), x + add)


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


def plane_filter(n: torch.Tensor, c: torch.Tensor, stride: int = 2) -> torch.Tensor:
    """Variance-preserving separable ``[c, 1, c]`` filter inside each CFA plane (same-colour pixels ``stride`` = 2
    px apart; 1: on the mosaic, adjacent pixels; borders reflected about each plane's edge pixel); ``c``
    broadcasts as ``[G, 1, 1, 1]``."""
    out = n
    h, w = n.shape[-2:]
    k = stride
    p = F.pad(out, (0, 0, k, k), mode="reflect")
    out = out + c * (p[..., 0:h, :] + p[..., 2 * k:h + 2 * k, :])
    p = F.pad(out, (k, k, 0, 0), mode="reflect")
    out = out + c * (p[..., :, 0:w] + p[..., :, 2 * k:w + 2 * k])
    return out / (1.0 + 2.0 * c * c)


def spatial_correlation(group: Group, x, ctx: Ctx, st: EffectState):
    cs = group.values(lambda e: e.coefficient)
    if not np.any(cs):
        return x
    c = ctx.scalar(group, lambda e: e.coefficient)
    if group.models[0].domain == "total":  # all the noise at read-out, cross kernel, variance kept
        scale = 1.0 / torch.sqrt((1 - 4 * c) ** 2 + 4 * c * c)
        zero = torch.zeros((), dtype=x.dtype, device=x.device)
        noise = charge_share(x - st.signal, c, zero) * scale
        st.read = charge_share(st.read, c, zero) * scale
        return st.signal + noise
    f = plane_filter(st.read, c, 2 if group.models[0].neighbours == "same_colour" else 1)
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
    cross = group.values(lambda e: e.cross_frequency)
    if np.any(cross):  # tilted bands: the phase also advances along the other axis
        fc = ctx.scalar(group, lambda e: e.cross_frequency, dtype=torch.float64).reshape(-1, 1)
        m = x.shape[-1 - ax]
        j = torch.arange(m, device=x.device, dtype=torch.float64)[None, :]
        if st.offsets is not None:
            j = j + torch.as_tensor(st.offsets[:, 1 - ax], dtype=torch.float64, device=x.device)[:, None]
        along = (2 * math.pi * i / period + phase)[:, :, None]  # [G, n, 1]
        grid = along + (2 * math.pi * fc * j)[:, None, :]  # [G, n, m]: n along the axis, m across
        wave = (amp[:, :, None] * torch.sin(grid)).to(x.dtype)
        return x + (wave[:, None] if e0.axis == "rows" else wave.transpose(1, 2)[:, None])
    wave = (amp * torch.sin(2 * math.pi * i / period + phase)).to(x.dtype)  # [G, n]
    return x + (wave[:, None, :, None] if e0.axis == "rows" else wave[:, None, None, :])


def nonlinearity(group: Group, x, ctx: Ctx, st: EffectState):
    s = ctx.scalar(group, lambda e: e.strength)
    return x - s * x * x


def empirical_response(group: Group, x, ctx: Ctx, st: EffectState):
    return x - st.fixed("strength") * x * x


def quantization(group: Group, x, ctx: Ctx, st: EffectState):
    """Rounded to the ADC step in DN (float64 arithmetic, round half to even as numpy); no gradient."""
    f = lambda name: ctx.scalar(group, lambda e: getattr(e, name), dtype=torch.float64)  # noqa: E731
    rng, step, off = f("range_dn"), f("step_dn"), f("offset_dn")
    dn = torch.round((x.detach().double() * rng + off) / step) * step
    return ((dn - off) / rng).to(x.dtype)


# -- effects added with measured maps, dark signal and ADC models -----------------

def dead_pixels(group: Group, x, ctx: Ctx, st: EffectState):
    """Stuck and dead pixels set; dead pixels that keep their read noise (``dead_read_noise``) read it."""
    x = torch.where(st.fixed("set_mask"), st.fixed("set_value"), x)
    if st.read is not None:
        x = torch.where(st.fixed("read_mask"), st.read, x)
    return x


def rtn(group: Group, x, ctx: Ctx, st: EffectState):
    """Each RTN pixel (fixed set, fixed amplitude) is in its high state with probability p_high, per frame."""
    p = ctx.scalar(group, lambda e: e.p_high)
    high = ctx.rand(x.shape) < p
    return x + torch.where(high, st.fixed("amp"), torch.zeros((), dtype=x.dtype, device=x.device))


def charge_share(q: torch.Tensor, c: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Charge-conserving sharing with the 4 adjacent (weight c) and 4 diagonal (d) pixels; borders reflect."""
    h, w = q.shape[-2:]
    p = F.pad(q, (1, 1, 1, 1), mode="reflect")

    def sh(dy, dx):
        return p[..., 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]

    adj = sh(-1, 0) + sh(1, 0) + sh(0, -1) + sh(0, 1)
    diag = sh(-1, -1) + sh(-1, 1) + sh(1, -1) + sh(1, 1)
    return (1.0 - 4.0 * c - 4.0 * d) * q + c * adj + d * diag


def charge_crosstalk(group: Group, x, ctx: Ctx, st: EffectState):
    """Signal and shot noise (x - read) shared with the neighbours before the read noise (charge conserved)."""
    cs = group.values(lambda e: (e.coefficient, e.diagonal))
    if not np.any(cs):
        return x
    if (4 * cs.sum(axis=1) >= 1).any():
        from ..errors import NoiseModelError

        raise NoiseModelError("charge_crosstalk: 4 (coefficient + diagonal) must be < 1")
    c = ctx.scalar(group, lambda e: e.coefficient)
    d = ctx.scalar(group, lambda e: e.diagonal)
    return charge_share(x - st.read, c, d) + st.read


def _codes(group: Group, x, ctx: Ctx, st: EffectState, first_code, step=lambda e: 1.0):
    rng = ctx.scalar(group, lambda e: e.range_dn, dtype=torch.float64)
    off = ctx.scalar(group, lambda e: e.offset_dn, dtype=torch.float64)
    q = ctx.scalar(group, step, dtype=torch.float64)
    analog = ((x.detach().double() * rng + off) / q).contiguous()
    edges = st.per_uniq("edges")

    def one(u, a):
        return torch.searchsorted(edges[u], a.reshape(-1), right=True).reshape(a.shape).double()

    code = _by_model(group, analog, one) + ctx.scalar(group, first_code, dtype=torch.float64)
    return ((code * q - off) / rng).to(x.dtype)


def adc_dnl(group: Group, x, ctx: Ctx, st: EffectState):
    """The ADC code of each value given the sensor's fixed transition levels (no gradient)."""
    return _codes(group, x, ctx, st, lambda e: 0.0, step=lambda e: e.step_dn)


def empirical_code(group: Group, x, ctx: Ctx, st: EffectState):
    """The code of each value given the measured transition levels (no gradient)."""
    return _codes(group, x, ctx, st, lambda e: e.first_code)


def dark_current(group: Group, x, ctx: Ctx, st: EffectState):
    """Poisson dark electrons of mean rate_i * t (rate_i: the fixed DCNU map, temperature-scaled)."""
    t = _exposure(st, "dark_current")
    base = ctx.scalar(group, lambda e: e.rate * e.scale(), dtype=torch.float64)
    el = ctx.scalar(group, lambda e: e.electron, dtype=torch.float64)
    rel = st.fixed("rate") if group.models[0].dcnu_log_sigma > 0 else None
    lam = base * t if rel is None else base * t * rel.double()
    return _poisson_electrons(x, lam, el, ctx)


def amp_glow(group: Group, x, ctx: Ctx, st: EffectState):
    """Poisson electrons of mean rate * t * glow field (the field of the full frame, cropped with offsets)."""
    t = _exposure(st, "amp_glow")
    rate = ctx.scalar(group, lambda e: e.rate, dtype=torch.float64)
    el = ctx.scalar(group, lambda e: e.electron, dtype=torch.float64)
    return _poisson_electrons(x, rate * t * st.fixed("field").double(), el, ctx)


def empirical_field(group: Group, x, ctx: Ctx, st: EffectState):
    """Poisson electrons of the measured dark field: ``electron * Poisson(rate * t / electron)``."""
    t = _exposure(st, "empirical_field")
    el = ctx.scalar(group, lambda e: e.electron, dtype=torch.float64)
    return _poisson_electrons(x, st.fixed("rate").double() * t / el, el, ctx)


def empirical_offset(group: Group, x, ctx: Ctx, st: EffectState):
    e0 = group.models[0]
    if any(e.rate != 0 for e in group.uniq):  # a black level rising with the exposure time
        x = x + (ctx.scalar(group, lambda e: e.rate, dtype=torch.float64) * _exposure(st, "empirical_offset")).to(x.dtype)
    if not e0.temporal:
        return x + st.fixed("offset")
    size = {"pixel": x.shape[-2:], "row": (x.shape[-2], 1), "column": (1, x.shape[-1]), "frame": (1, 1)}[e0.axis]
    qs = st.per_uniq("quantiles")
    scale = ctx.scalar(group, lambda e: e.scale, dtype=torch.float64)

    def one(u, rows):
        return _interp_quantiles(ctx.rand((rows.shape[0], 1, *size), dtype=torch.float64), qs[u])

    draws = _by_model(group, torch.empty((x.shape[0], 1, *size), dtype=torch.float64, device=x.device), one)
    return x + (scale * draws).to(x.dtype)


def empirical_spectrum(group: Group, x, ctx: Ctx, st: EffectState):
    """Per-frame line offsets by spectral synthesis: white normals filtered by the measured ``sqrt(S(f))``
    (the numpy effect's :meth:`~simcam.noise.effects.empirical.EmpiricalSpectrum.amplitudes` at this
    frame's number of lines) in the Fourier domain."""
    e0 = group.models[0]
    row = e0.axis == "row"
    n = x.shape[-2] if row else x.shape[-1]
    scale = ctx.scalar(group, lambda e: e.scale, dtype=torch.float64)

    def one(u, rows):
        amp = torch.as_tensor(group.uniq[u].amplitudes(n), dtype=torch.float64, device=x.device)
        z = torch.fft.rfft(ctx.randn((rows.shape[0], 1, n), dtype=torch.float64), dim=-1)
        return torch.fft.irfft(z * amp, n=n, dim=-1)

    draws = _by_model(group, torch.empty((x.shape[0], 1, n), dtype=torch.float64, device=x.device), one)
    draws = draws[..., :, None] if row else draws[..., None, :]
    return x + (scale * draws).to(x.dtype)


def empirical_gain(group: Group, x, ctx: Ctx, st: EffectState):
    return x * st.fixed("gain")


def empirical_lines(group: Group, x, ctx: Ctx, st: EffectState):
    x = x + st.fixed("offset")
    if any(m.has_gain for m in group.uniq):  # the lines' gain part acts on the expected signal (read-out stage)
        x = x + st.fixed("gain") * st.signal
    return x


#: torch implementation of every effect type (the registry test checks this against simcam's effect registry).
EFFECTS = {
    "prnu": prnu, "channel_gain": channel_gain, "frame_flicker": frame_flicker, "row_noise": row_noise,
    "column_fpn": column_fpn, "dsnu": dsnu, "black_level_offset": black_level_offset, "hot_pixels": hot_pixels,
    "heavy_tail_read": heavy_tail_read, "spatial_correlation": spatial_correlation,
    "periodic_pattern": periodic_pattern, "nonlinearity": nonlinearity, "quantization": quantization,
    "dead_pixels": dead_pixels, "rtn": rtn, "charge_crosstalk": charge_crosstalk, "adc_dnl": adc_dnl,
    "empirical_code": empirical_code, "dark_current": dark_current, "amp_glow": amp_glow,
    "empirical_field": empirical_field, "empirical_offset": empirical_offset, "empirical_gain": empirical_gain,
    "empirical_lines": empirical_lines, "empirical_spectrum": empirical_spectrum,
    "empirical_response": empirical_response,
}

#: fixed-draw keys that are 1-D tables, not maps (kept per distinct model, never cropped).
TABLES = ("edges", "quantiles")

#: effect types with no torch implementation, and why (none today; the registry test reads this).
EFFECTS_NOT_SUPPORTED: dict[str, str] = {}


def _map3(a, shape) -> np.ndarray:
    """A fixed map (H, W), (H, 1), (1, W) or (1, 1) cut to ``shape`` as float64 ``[1, h|1, w|1]``."""
    a = np.asarray(a, np.float64)
    a = a.reshape((1,) * (2 - a.ndim) + a.shape)[: shape[0], : shape[1]]
    return a[None]


def fixed_arrays(effect, fixed: dict[str, Any], shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """Host arrays ``[1, H|1, W|1]`` of one effect's fixed-pattern draw (numpy model's ``fixed``); 1-D
    ``edges`` / ``quantiles`` tables are returned as they are (keys listed in :data:`TABLES`)."""
    h, w = shape
    t = effect.type
    if t == "dead_pixels":
        mask = np.zeros(h * w, bool)
        val = np.zeros(h * w, np.float64)
        read_mask = np.zeros(h * w, bool)
        (read_mask if effect.needs_read else mask)[fixed["dead"]] = True
        mask[fixed["stuck"]] = True
        val[fixed["stuck"]] = fixed.get("stuck_value", np.float32(effect.stuck_value))
        return {"set_mask": mask.reshape(1, h, w), "set_value": val.reshape(1, h, w),
                "read_mask": read_mask.reshape(1, h, w)}
    if t == "rtn":
        amp = np.zeros(h * w, np.float64)
        amp[fixed["index"]] = fixed["amplitude"]
        return {"amp": amp.reshape(1, h, w)}
    if t in ("adc_dnl", "empirical_code"):
        return {"edges": np.asarray(fixed["edges"], np.float64)}
    if t == "dark_current":
        return {"rate": _map3(fixed["rate"], shape)} if "rate" in fixed else {}
    if t == "amp_glow":
        return {"field": effect.field(shape)[None]}
    if t == "empirical_field":
        return {"rate": _map3(fixed["rate"], shape)}
    if t == "empirical_offset":
        if effect.temporal:
            return {"quantiles": np.asarray(effect.quantiles, np.float64)}
        return {"offset": _map3(fixed["offset"], shape)}
    if t == "empirical_gain":
        return {"gain": _map3(fixed["gain"], shape)}
    if t == "empirical_lines":
        # a gain part always (zeros without one), so the samples of a group stack alike
        offset = _map3(fixed["offset"], shape)
        return {"offset": offset, "gain": _map3(fixed["gain"], shape) if "gain" in fixed else np.zeros_like(offset)}
    if t == "empirical_response":
        return {"strength": _map3(fixed["strength"], shape)}
    if effect.type == "column_fpn":
        return {"col": np.asarray(fixed["col"], np.float64)[:w].reshape(1, 1, w)}
    if effect.type == "dsnu":
        return {"offset": np.asarray(fixed["offset"], np.float64).reshape(1, h, w)}
    if effect.type == "prnu":
        return {"gain": np.asarray(fixed["gain"], np.float64).reshape(1, h, w)}
    if effect.type == "hot_pixels":
        add = np.zeros(h * w, np.float64)
        add[fixed["hot"]] = fixed.get("hot_offset", np.float32(effect.hot_offset))
        rate = np.zeros(h * w, np.float64)
        if "hot_rate" in fixed:
            rate[fixed["hot"]] = fixed["hot_rate"]
        mask = np.zeros(h * w, bool)
        val = np.zeros(h * w, np.float64)
        mask[fixed["stuck"]] = True
        val[fixed["stuck"]] = np.float32(effect.stuck_value)
        mask[fixed["dead"]] = True
        return {"add": add.reshape(1, h, w), "rate": rate.reshape(1, h, w), "set_mask": mask.reshape(1, h, w),
                "set_value": val.reshape(1, h, w)}
    return {}
