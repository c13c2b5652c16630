"""Per-pixel log-likelihoods on tensors (nats, float64), equal to the numpy models' ``log_prob``.

Closed forms for ``gaussian`` / ``nlf``; the windowed Poisson-weighted Gaussian
sum of :mod:`simcam.noise.poisson_gaussian` for ``poisson_gaussian`` and
``poisson_mixture`` (same window: centred on the precision-weighted mode,
half-width ``12 / sqrt(P_p + P_g) + 12`` terms); the censored likelihood for
``clipped``; for ``composite`` the likelihood given the fixed pattern of its
``sensor_seed`` when every effect is a signal transform, an offset or a
monotonic response (the numpy model's rule; otherwise it raises). Computed in
float64 and differentiable with respect to ``noisy`` and ``clean`` (the window
bounds are not).
"""

from __future__ import annotations

import math
from typing import Any

import torch

from ..errors import NoiseModelError
from .context import Ctx, sites
from .group import group_models, resolve_models
from .layout import MOSAIC, PACKED, layout_of, site_tensor, to_mosaic, to_packed

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_CHUNK = 1 << 15


def _site(group, ctx, fn):
    return site_tensor(group.values(lambda m: sites(fn(m))), ctx.layout, ctx.shape, device=ctx.device,
                       dtype=torch.float64)


def _normal(x, mean, var, where):
    if bool((var <= 0).any()):
        raise NoiseModelError(f"{where}: log_prob needs a positive variance, got 0 at {int((var <= 0).sum())} pixel(s)")
    r = (x - mean) / torch.sqrt(var)
    return -0.5 * r * r - 0.5 * torch.log(var) - _LOG_SQRT_2PI


def _gauss_var(group, clean, ctx):
    t = group.models[0].type
    if t == "gaussian":
        s = _site(group, ctx, lambda m: m.sigma)
        return (s * s).expand_as(clean)
    b1, b2 = _site(group, ctx, lambda m: m.beta1), _site(group, ctx, lambda m: m.beta2)
    return clean * b1 + b2


def _poisson_window(ls, lo, width, device):
    """The counts ``k = lo, lo + 1, ...`` of each element's Poisson window (rows padded to the widest),
    which of them are inside the ``width`` of the window, and ``log Pois(k; ls)``."""
    with torch.no_grad():
        kmax = int(width.max())
    j = torch.arange(kmax, device=device, dtype=torch.float64)[None, :]
    k = lo[:, None] + j
    valid = j < width[:, None]
    lcol = ls[:, None]
    logpois = torch.where(lcol > 0, k * torch.log(lcol.clamp_min(1e-300)) - lcol - torch.lgamma(k + 1.0),
                          torch.where(k == 0, torch.zeros_like(k), torch.full_like(k, -math.inf)))
    return k, valid, logpois


def pg_logpdf(x, lam, scale, var):
    """``log sum_k Pois(k; lam) N(x; scale k, var)`` elementwise (float64 1-D tensors, same window as numpy)."""
    out = torch.empty_like(x)
    pieces = []
    for s in range(0, x.numel(), _CHUNK):
        sl = slice(s, s + _CHUNK)
        xs, ls, ss, vs = x[sl], lam[sl], scale[sl], var[sl]
        with torch.no_grad():
            prec_p = 1.0 / ls.clamp_min(1.0)
            prec_g = ss * ss / vs
            kstar = (ls * prec_p + (xs / ss) * prec_g) / (prec_p + prec_g)
            half = torch.ceil(12.0 / torch.sqrt(prec_p + prec_g) + 12.0)
            lo = (kstar - half).floor().clamp_min(0.0)
            width = 2 * half + 1
        k, valid, logpois = _poisson_window(ls, lo, width, x.device)
        r = xs[:, None] - ss[:, None] * k
        lognorm = -0.5 * r * r / vs[:, None] - 0.5 * torch.log(vs[:, None]) - _LOG_SQRT_2PI
        terms = torch.where(valid, logpois + lognorm, torch.full_like(k, -math.inf))
        pieces.append(torch.logsumexp(terms, dim=1))
    return torch.cat(pieces) if pieces else out


def pg_logcdf(x, lam, scale, var, *, upper=False):
    """log P(noisy <= x) (or > x) under the Poisson-Gaussian law (Poisson window ``lam +- (12 sqrt(lam) + 12)``)."""
    pieces = []
    for s in range(0, x.numel(), _CHUNK):
        sl = slice(s, s + _CHUNK)
        xs, ls, ss, vs = x[sl], lam[sl], scale[sl], var[sl]
        with torch.no_grad():
            half = torch.ceil(12.0 * torch.sqrt(ls) + 12.0)
            lo = (ls - half).floor().clamp_min(0.0)
            width = (ls + half) - lo + 1
        k, valid, logpois = _poisson_window(ls, lo, width, x.device)
        r = (xs[:, None] - ss[:, None] * k) / torch.sqrt(vs[:, None])
        logc = torch.special.log_ndtr(-r if upper else r)
        pieces.append(torch.logsumexp(torch.where(valid, logpois + logc, torch.full_like(k, -math.inf)), dim=1))
    return torch.cat(pieces) if pieces else x.new_empty(0)


def _pg_parts(group, clean, ctx, where):
    b1 = _site(group, ctx, lambda m: m.beta1).expand_as(clean)
    b2 = _site(group, ctx, lambda m: m.beta2).expand_as(clean)
    if bool((b2 <= 0).any()):
        raise NoiseModelError(f"{where}: log_prob needs beta2 > 0 (a density)")
    return b1, b2


def _components(group, ctx):
    """[(log weight [G,1,1,1], z [G,1,1,1])] of a poisson_mixture group (weights 0 give -inf)."""
    p1 = ctx.scalar(group, lambda m: m.p1, dtype=torch.float64)
    z1 = ctx.scalar(group, lambda m: m.z1, dtype=torch.float64)
    z2 = ctx.scalar(group, lambda m: m.z2, dtype=torch.float64)
    return [(torch.log(p1), z1), (torch.log1p(-p1), z2)]


def _base_logpdf(group, y, clean, ctx):
    t = group.models[0].type
    if t in ("gaussian", "nlf"):
        return _normal(y, clean, _gauss_var(group, clean, ctx), t)
    if t == "poisson_gaussian":
        b1, b2 = _pg_parts(group, clean, ctx, t)
        return pg_logpdf(y.reshape(-1), (clean / b1).reshape(-1), b1.reshape(-1), b2.reshape(-1)).reshape(y.shape)
    if t == "poisson_mixture":
        b1, b2 = _pg_parts(group, clean, ctx, t)
        parts = []
        for lw, z in _components(group, ctx):
            s = (b1 * z).expand_as(clean)
            lp = pg_logpdf(y.reshape(-1), (clean / s).reshape(-1), s.reshape(-1), b2.reshape(-1)).reshape(y.shape)
            parts.append(lw + lp)
        return torch.logaddexp(parts[0], parts[1])
    if t == "clipped":
        return _clipped(group, y, clean, ctx)
    if t == "composite":
        return _composite(group, y, clean, ctx)
    raise NoiseModelError(f"model {t!r}: log_prob is not available in simcam.torch")


def _base_logcdf(group, x, clean, ctx, upper):
    t = group.models[0].type
    if t in ("gaussian", "nlf"):
        var = _gauss_var(group, clean, ctx)
        r = (x - clean) / torch.sqrt(var)
        return torch.special.log_ndtr(-r if upper else r)
    if t == "poisson_gaussian":
        b1, b2 = _pg_parts(group, clean, ctx, t)
        return pg_logcdf(x.reshape(-1), (clean / b1).reshape(-1), b1.reshape(-1), b2.reshape(-1),
                         upper=upper).reshape(clean.shape)
    if t == "poisson_mixture":
        b1, b2 = _pg_parts(group, clean, ctx, t)
        parts = []
        for lw, z in _components(group, ctx):
            s = (b1 * z).expand_as(clean)
            parts.append(lw + pg_logcdf(x.reshape(-1), (clean / s).reshape(-1), s.reshape(-1), b2.reshape(-1),
                                        upper=upper).reshape(clean.shape))
        return torch.logaddexp(parts[0], parts[1])
    raise NoiseModelError(f"model 'clipped': base {t!r} has no CDF, the censored likelihood needs one")


def _clipped(group, y, clean, ctx):
    base = group.sub(lambda m: m.base)
    lo = ctx.scalar(group, lambda m: m.low, dtype=torch.float64)
    hi = ctx.scalar(group, lambda m: m.high, dtype=torch.float64)
    if bool(((y < lo) | (y > hi)).any()):
        raise NoiseModelError("noisy: expected clipped values inside [low, high] of the clipped model")
    at_lo, at_hi = y <= lo, y >= hi
    inside = _base_logpdf(base, y, clean, ctx)
    out = torch.where(at_lo, _base_logcdf(base, lo.expand_as(y), clean, ctx, False), inside)
    return torch.where(at_hi, _base_logcdf(base, hi.expand_as(y), clean, ctx, True), out)


def _composite(group, y, clean, ctx):
    from .composite import fixed_tensors, _stacked
    from .effects import EFFECTS, EffectState

    effects = group.models[0].effects
    bad = [e.type for e in effects if e.role() is None]
    if bad:
        raise NoiseModelError(f"model 'composite': log_prob is not tractable with effect(s) {bad} "
                              f"(random per frame or discretising)")
    shape = tuple(clean.shape[-2:])
    # the numpy composite computes the signal and the offsets in float32: so do we (then float64)
    from dataclasses import replace

    c32 = replace(ctx, dtype=torch.float32)
    fixed = [fixed_tensors(m, shape, ctx.device, torch.float32) for m in group.uniq]
    eg = [group.sub(lambda m, i=i: m.effects[i]) for i in range(len(effects))]
    signal = clean.float()
    for i, e in enumerate(effects):
        if e.stage == "signal":
            signal = EFFECTS[e.type](eg[i], signal, c32, EffectState(_stacked(group, fixed, i)))
    signal = signal.double()
    y = y.float().double()  # the numpy model rounds the observation to float32 first
    log_jac = torch.zeros_like(y)
    for i in reversed(range(len(effects))):
        e = effects[i]
        if e.stage == "signal":
            continue
        if e.role() == "response":
            s = ctx.scalar(eg[i], lambda m: m.strength, dtype=torch.float64)
            disc = (1.0 - 4.0 * s * y).clamp_min(0.0)
            y = 2.0 * y / (1.0 + torch.sqrt(disc))
            log_jac = log_jac + torch.log(torch.abs(1.0 - 2.0 * s * y))
        else:
            zero = torch.zeros(y.shape, dtype=torch.float32, device=y.device)
            state = EffectState(_stacked(group, fixed, i), signal=signal.float())
            y = y - EFFECTS[e.type](eg[i], zero, c32, state).double()
    return _base_logpdf(group.sub(lambda m: m.base), y, signal, ctx) - log_jac


def log_prob(noisy: torch.Tensor, clean: torch.Tensor, profile_or_model: Any, *, iso: Any = None,
             camera: Any = None, extrapolate: bool = False) -> torch.Tensor:
    """Per-pixel log-likelihood (nats, float64, shape of ``clean``) of ``noisy`` given ``clean``.

    Same layouts and model sources as :func:`simcam.torch.add_noise`; equal to the numpy model's
    ``log_prob`` on the same values (the composite's is given its ``sensor_seed`` fixed pattern).

    Parameters
    ----------
    noisy, clean : Tensor
        The same shape: packed ``[B, 4, h, w]`` or mosaic ``[B, 1, H, W]`` normalised raw.
    profile_or_model
        As :func:`simcam.torch.add_noise` (not a Noise Flow).
    iso, camera, extrapolate
        As :func:`simcam.torch.add_noise`.

    Returns
    -------
    Tensor
        float64 log-density per pixel, shape of ``clean``.

    Examples
    --------
    >>> import torch
    >>> clean = torch.full((1, 1, 2, 2), 0.25)
    >>> lp = log_prob(clean + 0.01, clean, {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5})
    >>> lp.dtype, bool((lp < log_prob(clean, clean, {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5})).all())
    (torch.float64, True)
    """
    layout = layout_of(clean)
    if noisy.shape != clean.shape:
        raise NoiseModelError(f"noisy: expected the clean batch's shape {tuple(clean.shape)}, got {tuple(noisy.shape)}")
    models = resolve_models(profile_or_model, clean.shape[0], iso=iso, camera=camera, extrapolate=extrapolate)
    c64, y64 = clean.double(), noisy.double()
    out = torch.empty_like(c64)
    for g in group_models(models):
        idx = torch.as_tensor(g.index, device=clean.device)
        c, y = c64.index_select(0, idx), y64.index_select(0, idx)
        mosaic = g.models[0].type in ("composite", "clipped") and layout == PACKED
        if mosaic:
            c, y = to_mosaic(c), to_mosaic(y)
        ctx = Ctx(device=clean.device, dtype=torch.float64, layout=MOSAIC if mosaic else layout,
                  shape=tuple(c.shape[-2:]), generator=None)
        lp = _base_logpdf(g, y, c, ctx)
        out = out.index_copy(0, idx, to_packed(lp) if mosaic else lp)
    return out
