"""Tensor layouts of raw batches: packed ``[B, 4, h, w]`` and mosaic ``[B, 1, H, W]``.

Packed channels are the 2 x 2 CFA sites in the order (0,0), (0,1), (1,0), (1,1)
of :mod:`simcam.cfa` (``pack``); the mosaic's pixel (0, 0) is CFA site (0, 0).
:func:`to_mosaic` / :func:`to_packed` are ``pixel_shuffle`` / ``pixel_unshuffle``
with factor 2 (computed as one strided copy), whose channel index ``2 dy + dx`` is exactly that order.
"""

from __future__ import annotations

import numpy as np
import torch

from ..errors import NoiseModelError

PACKED = "packed"
MOSAIC = "mosaic"


def layout_of(x: torch.Tensor, *, where: str = "clean") -> str:
    """``"packed"`` for ``[B, 4, h, w]``, ``"mosaic"`` for ``[B, 1, H, W]``; else NoiseModelError."""
    if not isinstance(x, torch.Tensor):
        raise NoiseModelError(f"{where}: expected a torch tensor, got {type(x).__name__}")
    if x.ndim != 4 or x.shape[1] not in (1, 4):
        raise NoiseModelError(f"{where}: expected a packed [B, 4, h, w] or mosaic [B, 1, H, W] tensor, "
                              f"got shape {tuple(x.shape)}")
    if not x.is_floating_point():
        raise NoiseModelError(f"{where}: expected a floating-point tensor, got {x.dtype}")
    return PACKED if x.shape[1] == 4 else MOSAIC


def to_mosaic(x: torch.Tensor) -> torch.Tensor:
    """Packed ``[B, 4, h, w]`` -> mosaic ``[B, 1, 2h, 2w]`` (= ``pixel_shuffle(x, 2)``; one strided copy).

    Parameters
    ----------
    x : Tensor
        Packed batch: channels are the CFA sites (0,0), (0,1), (1,0), (1,1).

    Returns
    -------
    Tensor
        The mosaic batch.

    Examples
    --------
    >>> import torch
    >>> to_mosaic(torch.arange(4.0).reshape(1, 4, 1, 1)).flatten().tolist()
    [0.0, 1.0, 2.0, 3.0]
    """
    b, _, h, w = x.shape
    out = torch.empty((b, h, 2, w, 2), dtype=x.dtype, device=x.device)
    out.copy_(x.reshape(b, 2, 2, h, w).permute(0, 3, 1, 4, 2))
    return out.view(b, 1, 2 * h, 2 * w)


def to_packed(x: torch.Tensor) -> torch.Tensor:
    """Mosaic ``[B, 1, H, W]`` (H, W even) -> packed ``[B, 4, H/2, W/2]``.

    Parameters
    ----------
    x : Tensor
        Mosaic batch whose pixel (0, 0) is CFA site (0, 0).

    Returns
    -------
    Tensor
        The packed batch (inverse of :func:`to_mosaic`).

    Examples
    --------
    >>> import torch
    >>> m = torch.arange(16.0).reshape(1, 1, 4, 4)
    >>> to_packed(m).shape, torch.equal(to_mosaic(to_packed(m)), m)
    (torch.Size([1, 4, 2, 2]), True)
    """
    if x.shape[-2] % 2 or x.shape[-1] % 2:
        raise NoiseModelError(f"clean: packing needs an even mosaic height and width, got {x.shape[-2]}x{x.shape[-1]}")
    b, _, hh, ww = x.shape
    out = torch.empty((b, 2, 2, hh // 2, ww // 2), dtype=x.dtype, device=x.device)
    out.copy_(x.reshape(b, hh // 2, 2, ww // 2, 2).permute(0, 2, 4, 1, 3))
    return out.view(b, 4, hh // 2, ww // 2)


def site_tensor(values: np.ndarray, layout: str, shape: tuple[int, int], *, device, dtype) -> torch.Tensor:
    """Per-CFA-site values ``[G, 4]`` (host array) as a tensor broadcasting against ``[G, C, h, w]``.

    Packed: ``[G, 4, 1, 1]``. Mosaic: ``[G, 1, H, W]`` (the 2 x 2 cell tiled from row 0 /
    column 0; odd sizes cropped), or ``[G, 1, 1, 1]`` when the four sites agree in every row.
    """
    v = np.asarray(values, dtype=np.float64)
    g = v.shape[0]
    t = torch.as_tensor(v, dtype=dtype).to(device, non_blocking=True)
    if layout == PACKED:
        return t.reshape(g, 4, 1, 1)
    if (v == v[:, :1]).all():
        return t[:, :1].reshape(g, 1, 1, 1)
    h, w = shape
    return t.reshape(g, 1, 2, 2).repeat(1, 1, (h + 1) // 2, (w + 1) // 2)[..., :h, :w]


def scalar_tensor(values: np.ndarray, *, device, dtype) -> torch.Tensor:
    """Per-sample scalars ``[G]`` (host array) as a ``[G, 1, 1, 1]`` tensor."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    return torch.as_tensor(v, dtype=dtype).to(device, non_blocking=True).reshape(-1, 1, 1, 1)
