"""CFA plane views of a mosaic (works for odd sizes and for monochrome sensors)."""

from __future__ import annotations

import numpy as np

from ..cfa import PACK_OFFSETS


def plane_offsets(cfa: str | None) -> tuple[tuple[int, int], ...]:
    """(row, col) offsets of the CFA planes: the four Bayer sites, or ((0, 0),) for mono.

    For a monochrome sensor (``cfa`` None) the one plane is the whole image with
    step 1; for a Bayer mosaic each plane is ``data[dy::2, dx::2]``.
    """
    return ((0, 0),) if cfa is None else PACK_OFFSETS


def plane_step(cfa: str | None) -> int:
    """Pixel step of one CFA plane in the mosaic: 1 (mono) or 2 (Bayer)."""
    return 1 if cfa is None else 2


def planes(data: np.ndarray, cfa: str | None) -> list[np.ndarray]:
    """Views ``data[dy::s, dx::s]`` of each CFA plane (no copy)."""
    s = plane_step(cfa)
    return [data[dy::s, dx::s] for dy, dx in plane_offsets(cfa)]


def luma(data: np.ndarray, cfa: str | None) -> np.ndarray:
    """Registration image: the mosaic (mono) or the mean of the four Bayer planes (half size).

    float32; the Bayer version is cropped to the common even size. Its pixel
    pitch is :func:`plane_step` mosaic pixels.
    """
    if cfa is None:
        return np.asarray(data, dtype=np.float32)
    h, w = (data.shape[0] // 2) * 2, (data.shape[1] // 2) * 2
    d = data[:h, :w]
    return (0.25 * (d[0::2, 0::2].astype(np.float32) + d[0::2, 1::2] + d[1::2, 0::2] + d[1::2, 1::2])).astype(np.float32)
