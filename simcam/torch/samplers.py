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
from .context import Ctx
from .group import Group

#: largest Poisson mean sampled (as the numpy ``poisson_gaussian``: integer counts exact in float32).
LAMBDA_MAX = float(2**22)


def gaussian(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """``clean + sigma * z``, z ~ N(0, 1)."""
    sd = ctx.site(group, lambda m: m.sigma)
    return clean + sd * ctx.randn(clean.shape)


def nlf(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """``clean + sqrt(beta1 clean + beta2) * z``, z ~ N(0, 1) (reparameterised)."""
    b1 = ctx.site(group, lambda m: m.beta1)
    b2 = ctx.site(group, lambda m: m.beta2)
    var = clean * b1 + b2
    return clean + torch.sqrt(var.clamp_min(0)) * ctx.randn(clean.shape)


def poisson_scaled(clean: torch.Tensor, scale: torch.Tensor, beta2: torch.Tensor, ctx: Ctx, *, where: str) -> torch.Tensor:
    """``scale * Poisson(clean / scale) + sqrt(beta2) * z``, exact (``torch.poisson``)."""
    lam = clean.detach() / scale
    if ctx.validate and lam.numel():
        lam_max = float(lam.max())
        if lam_max >= LAMBDA_MAX:
            raise NoiseModelError(f"{where}: beta1 gives a Poisson mean of {lam_max:.3g} photo-electrons; expected "
                                  f"below {LAMBDA_MAX:.3g} (use the nlf model for such signals)")
    work = lam if lam.dtype in (torch.float32, torch.float64) else lam.float()
    k = torch.poisson(work, generator=ctx.generator).to(clean.dtype)
    return scale * k + torch.sqrt(beta2) * ctx.randn(clean.shape)


def poisson_gaussian(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """``beta1 * Poisson(clean / beta1) + N(0, beta2)``."""
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
    from .dispatch import sample_group

    x = sample_group(group.sub(lambda m: m.base), clean, ctx)
    lo = ctx.scalar(group, lambda m: m.low)
    hi = ctx.scalar(group, lambda m: m.high)
    return torch.minimum(torch.maximum(x, lo), hi)
