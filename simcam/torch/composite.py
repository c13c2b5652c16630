"""``composite`` on tensors: signal-stage effects, base model, read noise apart, readout effects.

The order of operations is that of :class:`simcam.noise.composite.Composite`:
signal effects in list order on the expected signal; the base model (without
its signal-independent Gaussian read part when an effect acts on the read
noise alone, which is then drawn apart and added); readout effects in list
order on the noisy value. Works on the mosaic layout ``[G, 1, H, W]``.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import torch

from ..errors import NoiseModelError
from .context import Ctx, sites
from .effects import EFFECTS, TABLES, EffectState, fixed_arrays
from .group import Group, entry_key

_FIXED_CACHE: "OrderedDict[tuple, list[dict[str, torch.Tensor]]]" = OrderedDict()
_FIXED_CACHE_SIZE = 16


def fixed_tensors(model, shape: tuple[int, int], device, dtype) -> list[dict[str, torch.Tensor]]:
    """Device tensors ``[1, 1, H, W]`` (or ``[1, 1, 1, W]``) of a composite's fixed patterns (cached)."""
    key = (entry_key(model), tuple(shape), str(device), str(dtype))
    hit = _FIXED_CACHE.get(key)
    if hit is not None:
        _FIXED_CACHE.move_to_end(key)
        return hit
    draws = model.fixed_patterns(tuple(shape))
    out = []
    for e, d in zip(model.effects, draws):
        arrays = fixed_arrays(e, d, shape)
        out.append({k: torch.as_tensor(a[:, None] if a.ndim == 3 else a,
                                       dtype=torch.float64 if k in TABLES else
                                       torch.bool if a.dtype == bool else dtype).to(device)
                    for k, a in arrays.items()})
    _FIXED_CACHE[key] = out
    while len(_FIXED_CACHE) > _FIXED_CACHE_SIZE:
        _FIXED_CACHE.popitem(last=False)
    return out


def crop(t: torch.Tensor, offsets: np.ndarray, shape: tuple[int, int], which=None) -> torch.Tensor:
    """Per-sample crops ``[G, 1, h or 1, w or 1]`` of full-frame maps ``t`` ``[T, 1, FH or 1, FW or 1]``
    at mosaic ``offsets`` ``[G, 2]`` (``which[g]``: the map of sample g, default 0)."""
    dev = t.device
    g = offsets.shape[0]
    h = shape[0] if t.shape[-2] > 1 else 1
    w = shape[1] if t.shape[-1] > 1 else 1
    oy = torch.as_tensor(offsets[:, 0] if t.shape[-2] > 1 else np.zeros(g, np.int64), device=dev)
    ox = torch.as_tensor(offsets[:, 1] if t.shape[-1] > 1 else np.zeros(g, np.int64), device=dev)
    rows = oy[:, None, None] + torch.arange(h, device=dev)[None, :, None]
    cols = ox[:, None, None] + torch.arange(w, device=dev)[None, None, :]
    k = torch.zeros(g, dtype=torch.int64, device=dev) if which is None else torch.as_tensor(which, device=dev)
    return t[k[:, None, None], 0, rows, cols][:, None]


def _stacked(group: Group, per_uniq: list[list[dict]], i: int, offsets=None, shape=None):
    def get(name: str) -> torch.Tensor:
        ts = [u[i][name] for u in per_uniq]
        if offsets is not None:
            return crop(torch.cat(ts), offsets, shape, None if group.shared else group.inv)
        if group.shared:
            return ts[0]
        return torch.cat(ts)[torch.as_tensor(group.inv, device=ts[0].device)]
    return get


def composite(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    sample_group = ctx.sample_group
    shape = tuple(clean.shape[-2:])
    offsets = ctx.offsets_of(group)
    fshape = shape if offsets is None else tuple(ctx.frame_shape)
    fixed = [fixed_tensors(m, fshape, ctx.device, ctx.dtype) for m in group.uniq]
    effects = group.models[0].effects
    egroups = [group.sub(lambda m, i=i: m.effects[i]) for i in range(len(effects))]
    exp = None if ctx.exposure_s is None else torch.as_tensor(
        ctx.exposure_s[np.asarray(group.index)], dtype=torch.float64).to(ctx.device).reshape(-1, 1, 1, 1)
    states = [EffectState(_stacked(group, fixed, i, offsets, shape), offsets=offsets,
                          per_uniq=lambda name, i=i: [u[i][name] for u in fixed], exposure_s=exp)
              for i in range(len(effects))]
    signal = clean
    for i, e in enumerate(effects):
        if e.stage == "signal":
            signal = EFFECTS[e.type](egroups[i], signal, ctx, states[i])
    needs_read = any(e.needs_read for e in effects)
    read = None
    if needs_read:
        splits = [m.base.read_split() for m in group.uniq]
        if any(s is None for s in splits):
            raise NoiseModelError(f"composite: effects {[e.type for e in effects if e.needs_read]} act on the read noise "
                                  f"but base model {group.models[0].base.type!r} has no separate read-noise part "
                                  f"(use poisson_gaussian, nlf or gaussian)")
        lookup = {entry_key(m): s for m, s in zip(group.uniq, splits)}
        base_group = group.sub(lambda m: lookup[entry_key(m)][0])
        var = group.values(lambda m: sites(lookup[entry_key(m)][1]))
        from .layout import site_tensor

        sd = torch.sqrt(site_tensor(var, ctx.layout, ctx.shape, device=ctx.device, dtype=ctx.dtype))
        x = sample_group(base_group, signal, ctx)
        read = sd * ctx.randn(clean.shape)
        x = x + read
    else:
        x = sample_group(group.sub(lambda m: m.base), signal, ctx)
    for i, e in enumerate(effects):
        if e.stage == "readout":
            states[i].read = read
            states[i].signal = signal
            x = EFFECTS[e.type](egroups[i], x, ctx, states[i])
            read = states[i].read
    return x
