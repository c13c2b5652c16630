"""Base noise models on tensors: ``gaussian``, ``nlf``, ``poisson_gaussian``, ``poisson_mixture``, ``clipped``.

Each function draws from the same law as the numpy model of the same ``type``
(:mod:`simcam.noise`), with the same parameter meanings: per-CFA-site
parameters in the packed site order (0,0), (0,1), (1,0), (1,1), normalised raw
units, clipping only in ``clipped``.

Differentiability. ``gaussian`` and ``nlf`` are reparameterised
(``clean + sqrt(var(clean)) * z``): gradients flow to ``clean`` (and through
it to anything upstream). The Poisson draws of ``poisson_gaussian`` and
``poisson_mixture`` are discrete: ``torch.poisson`` has no gradient with
respect to its rate, so those models pass no gradient to ``clean`` (the
Gaussian read part adds none either, it does not depend on ``clean``).
``clipped`` passes the gradient of its base inside ``(low, high)`` and zero
where it clips.
"""

from __future__ import annotations

import torch

from ..errors import NoiseModelError
from .context import Ctx, sites
from .group import Group

#: largest Poisson mean sampled (as the numpy ``poisson_gaussian``: integer counts exact in float32).
LAMBDA_MAX = float(2**22)


def gaussian(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """``clean + sigma * z``, z ~ N(0, 1)."""
    sd = ctx.site(group, lambda m: m.sigma)
    return clean + sd * ctx.randn(clean.shape)


def _nlf_host(group: Group, clean: torch.Tensor, ctx: Ctx):
    """CPU float32 fast path for one NLF with site-independent betas: simcam's fused compiled NLF kernel
    (one pass, no temporaries), its numpy generator started from a draw of ``ctx.generator``; None when it does not apply."""
    if not (clean.device.type == "cpu" and clean.dtype == torch.float32 and not clean.requires_grad
            and group.shared and clean.is_contiguous()):
        return None
    m = group.uniq[0]
    b1, b2 = sites(m.beta1), sites(m.beta2)
    if (b1 != b1[0]).any() or (b2 != b2[0]).any():
        return None
    try:  # the kernel module may move; the torch path below is the same law
        from ..noise.kernels.nlf import nlf_noise
    except ImportError:  # pragma: no cover
        return None
    import numpy as np

    rng = np.random.default_rng(int(torch.randint(0, 2**62, (1,), generator=ctx.generator)))
    out = torch.empty_like(clean)
    nlf_noise(clean.numpy(), float(b1[0]), float(b2[0]), rng, clip=None, out=out.numpy())
    return out


def nlf(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """``clean + sqrt(beta1 clean + beta2) * z``, z ~ N(0, 1) (reparameterised).

    On the CPU (float32, no gradient, one model with site-independent betas) this runs simcam's fused
    NLF kernel; elsewhere torch operations. Same law; the bytes differ.
    """
    fast = _nlf_host(group, clean, ctx)
    if fast is not None:
        return fast
    b1 = ctx.site(group, lambda m: m.beta1)
    b2 = ctx.site(group, lambda m: m.beta2)
    z = ctx.randn(clean.shape)
    if clean.requires_grad or b1.requires_grad:
        return clean + torch.sqrt((clean * b1 + b2).clamp_min(0)) * z
    sd = torch.addcmul(b2, clean, b1).sqrt_()  # >= 0 for clean >= 0 (validated); NaN otherwise, as numpy
    return torch.addcmul(clean, z, sd, out=z)


def poisson_scaled(clean: torch.Tensor, scale: torch.Tensor, beta2: torch.Tensor, ctx: Ctx, *, where: str) -> torch.Tensor:
    """``scale * Poisson(clean / scale) + sqrt(beta2) * z``, exact (``torch.poisson``)."""
    lam = clean.detach() / scale
    if ctx.validate and lam.numel():
        lam_max = float(lam.max())
        if lam_max >= LAMBDA_MAX:
            raise NoiseModelError(f"{where}: beta1 gives a Poisson mean of {lam_max:.3g} photo-electrons; expected "
                                  f"below {LAMBDA_MAX:.3g} (use the nlf model for such signals)")
    work = lam if lam.dtype in (torch.float32, torch.float64) else lam.float()
    k = ctx.poisson(work).to(clean.dtype)
    z = ctx.randn(clean.shape)
    if scale.requires_grad or beta2.requires_grad:
        return scale * k + torch.sqrt(beta2) * z
    return z.mul_(torch.sqrt(beta2)).addcmul_(scale, k)  # in place: no temporaries


def _pg_host(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """CPU float32 fast path: simcam's own exact sampler (alias tables, compiled kernel) through the public
    ``NoiseModel.sample_stack``, its numpy generator started from a draw of ``ctx.generator`` (so still deterministic
    given it)."""
    import numpy as np

    from ..noise import NoiseCondition
    from .layout import PACKED, to_mosaic, to_packed

    seed = int(torch.randint(0, 2**62, (1,), generator=ctx.generator))
    rng = np.random.default_rng(seed)
    flat = all((sites(m.beta1) == sites(m.beta1)[0]).all() and (sites(m.beta2) == sites(m.beta2)[0]).all()
               for m in group.uniq)
    if flat:  # site-independent parameters: pixel order is irrelevant, no re-layout (G x C*h x w frames)
        g, c, h, w = clean.shape
        src = clean.detach().contiguous().reshape(g, c * h, w).numpy()
    else:
        mosaic = to_mosaic(clean) if ctx.layout == PACKED else clean
        src = mosaic[:, 0].detach().contiguous().numpy()
    cond = NoiseCondition(cfa="RGGB", source="clean")
    if group.shared:
        out = group.uniq[0].sample_stack(src, cond, rng)
    else:
        out = np.empty_like(src)
        for u, model in enumerate(group.uniq):
            sel = np.flatnonzero(group.inv == u)
            out[sel] = model.sample_stack(src[sel], cond, rng)
    t = torch.from_numpy(out)
    if flat:
        return t.reshape(clean.shape)
    t = t[:, None]
    return to_packed(t) if ctx.layout == PACKED else t


def _host_ok(clean: torch.Tensor, ctx: Ctx) -> bool:
    h = clean.shape[-2] * clean.shape[-3]  # packed: 4h; mosaic: H (even for the stacked frames and CFA cells)
    return clean.device.type == "cpu" and clean.dtype == torch.float32 and h % 2 == 0 and not clean.requires_grad


def poisson_gaussian(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """``beta1 * Poisson(clean / beta1) + N(0, beta2)``.

    On the CPU (float32) this calls simcam's exact alias-table sampler (several times faster than
    ``torch.poisson`` there); elsewhere ``torch.poisson``. Both are exact; the bytes differ.
    """
    if _host_ok(clean, ctx):
        return _pg_host(group, clean, ctx)
    b1 = ctx.site(group, lambda m: m.beta1)
    b2 = ctx.site(group, lambda m: m.beta2)
    return poisson_scaled(clean, b1, b2, ctx, where="poisson_gaussian")


def poisson_mixture(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """Per pixel ``s = beta1 * (z1 if u < p1 else z2)``, ``s * Poisson(clean / s) + N(0, beta2)``."""
    b1 = ctx.site(group, lambda m: m.beta1)
    b2 = ctx.site(group, lambda m: m.beta2)
    p1 = ctx.scalar(group, lambda m: m.p1)
    z1 = ctx.scalar(group, lambda m: m.z1)
    z2 = ctx.scalar(group, lambda m: m.z2)
    pick1 = ctx.rand(clean.shape) < p1
    scale = torch.where(pick1, z1, z2) * b1
    return poisson_scaled(clean, scale, b2, ctx, where="poisson_mixture")


def clipped(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """The base model's sample clamped to ``[low, high]``."""
    x = ctx.sample_group(group.sub(lambda m: m.base), clean, ctx)
    lo = ctx.scalar(group, lambda m: m.low)
    hi = ctx.scalar(group, lambda m: m.high)
    return torch.minimum(torch.maximum(x, lo), hi)
