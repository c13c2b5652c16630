"""Helpers shared by the Noise Flow tests (not a test module)."""

from __future__ import annotations

import numpy as np

#: released packed order (0,0),(0,1),(1,1),(1,0) -> simcam (0,0),(0,1),(1,0),(1,1)
TO_SIMCAM = [0, 1, 3, 2]


def nhwc_released_to_nchw(a):
    """Golden array [B, H, W, 4] in the released channel order -> simcam NCHW."""
    return np.ascontiguousarray(np.asarray(a)[..., TO_SIMCAM].transpose(0, 3, 1, 2))


def nhwc_latent_to_nchw(a):
    """Golden latent [B, H, W, 4] -> NCHW (the latent keeps the model's own order)."""
    return np.ascontiguousarray(np.asarray(a).transpose(0, 3, 1, 2))


def randomise(flow, seed=0, scale=0.3):
    """Give every parameter a random non-trivial value (couplings start as identity)."""
    import torch

    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in flow.named_parameters():
            p.add_(scale * torch.randn(p.shape, generator=g, dtype=p.dtype))
    return flow
