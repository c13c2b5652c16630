"""What the torch samplers share for one call: device, dtype, layout, shape and generator."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
import torch

from .layout import scalar_tensor, site_tensor


def sites(value) -> np.ndarray:
    """A per-site parameter (float or 4 floats, site order (0,0), (0,1), (1,0), (1,1)) as 4 float64 values."""
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    return np.repeat(v, 4) if v.size == 1 else v


@dataclass(frozen=True)
class Ctx:
    """Call context (immutable; :meth:`with_layout` for the mosaic view of a packed batch)."""

    device: torch.device
    dtype: torch.dtype
    layout: str
    shape: tuple[int, int]
    generator: torch.Generator | None
    validate: bool = True
    #: full-frame (H, W) of the fixed patterns and each sample's (row, column) crop offset, or None
    frame_shape: tuple[int, int] | None = None
    offsets: np.ndarray | None = None  # [B, 2] int64, mosaic pixels, even
    #: each sample's exposure time in seconds (dark_current, amp_glow, empirical_field), or None
    exposure_s: np.ndarray | None = None
    #: the dispatcher (``dispatch.sample_group``), for models that sample a base model (composite,
    #: clipped) without importing the module that imports them
    sample_group: Callable | None = None

    def offsets_of(self, group) -> np.ndarray | None:
        """The crop offsets ``[G, 2]`` of a group's samples (None without ``frame_shape``)."""
        return None if self.offsets is None else self.offsets[np.asarray(group.index)]

    def with_layout(self, layout: str, shape: tuple[int, int]) -> "Ctx":
        return replace(self, layout=layout, shape=shape)

    def site(self, group, fn) -> torch.Tensor:
        """Per-site parameter ``fn(model)`` of every sample, broadcastable against the batch."""
        return site_tensor(group.values(lambda m: sites(fn(m))), self.layout, self.shape, device=self.device,
                           dtype=self.dtype)

    def scalar(self, group, fn, dtype=None) -> torch.Tensor:
        """Scalar parameter ``fn(model)`` of every sample as ``[G or 1, 1, 1, 1]``."""
        return scalar_tensor(group.values(fn), device=self.device, dtype=dtype or self.dtype)

    def randn(self, shape, dtype=None) -> torch.Tensor:
        return torch.randn(shape, generator=self.generator, device=self.device, dtype=dtype or self.dtype)

    def rand(self, shape, dtype=None) -> torch.Tensor:
        return torch.rand(shape, generator=self.generator, device=self.device, dtype=dtype or self.dtype)

    def poisson(self, lam: torch.Tensor) -> torch.Tensor:
        """``torch.poisson(lam)`` from the batch's generator. On CUDA each call draws from a generator of its
        own, seeded by one draw of the batch's: PyTorch's CUDA Poisson kernel (seen with torch 2.11) reserves
        too few Philox numbers per element, so two consecutive calls on one generator gave draws correlated
        at +0.34 (lambda 30; and -0.006 with the normals drawn next), which raised the variance of every
        composite with two Poisson terms (shot noise and dark charge). Deterministic: the seed comes from
        the batch's generator."""
        if lam.device.type != "cuda":
            return torch.poisson(lam, generator=self.generator)
        seed = int(torch.randint(0, 2 ** 62, (1,), generator=self.generator, device=lam.device).item())
        return torch.poisson(lam, generator=torch.Generator(device=lam.device).manual_seed(seed))
