"""What the torch samplers share for one call: device, dtype, layout, shape and generator."""

from __future__ import annotations

from dataclasses import dataclass, replace

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
