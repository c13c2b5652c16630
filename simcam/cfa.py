"""Bayer colour-filter-array helpers.

Patterns are 4-letter strings read row-major over the 2x2 cell, e.g. ``"RGGB"``
means ``R`` at (0, 0), ``G`` at (0, 1), ``G`` at (1, 0), ``B`` at (1, 1).
Conversion to OpenCV/kornia codes happens only at a boundary (their "BG" names
the opposite corner).
"""

from __future__ import annotations

import numpy as np

from .errors import CfaError

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
#: Packed channel order used everywhere in simcam: (0,0), (0,1), (1,0), (1,1).
PACK_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


def check_pattern(cfa: str, *, where: str = "cfa") -> str:
    """Return ``cfa`` upper-cased, or raise :class:`~simcam.errors.CfaError` if it is not a 2x2 Bayer pattern."""
    if not isinstance(cfa, str) or cfa.upper() not in BAYER_PATTERNS:
        raise CfaError(f"{where}: expected one of {', '.join(BAYER_PATTERNS)}, got {cfa!r}")
    return cfa.upper()


def shift_pattern(cfa: str, row: int, col: int) -> str:
    """Pattern seen by an image whose (0, 0) is (row, col) of the original."""
    cfa = check_pattern(cfa)
    dy, dx = row % 2, col % 2
    return "".join(cfa[2 * ((r + dy) % 2) + (c + dx) % 2] for r in (0, 1) for c in (0, 1))


def channel_masks(cfa: str, shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """Boolean masks ``{"R": ..., "G": ..., "B": ...}`` of an H x W mosaic."""
    cfa = check_pattern(cfa)
    masks = {c: np.zeros(shape, dtype=bool) for c in "RGB"}
    for (dy, dx), c in zip(PACK_OFFSETS, cfa):
        masks[c][dy::2, dx::2] = True
    return masks


def site_colour_index(cfa: str) -> np.ndarray:
    """2x2 array of colour indices (0=R, 1=G, 2=B) of each CFA site."""
    cfa = check_pattern(cfa)
    return np.array(["RGB".index(c) for c in cfa]).reshape(2, 2)


def pack(mosaic: np.ndarray) -> np.ndarray:
    """H x W mosaic -> 4 x H/2 x W/2, channels in :data:`PACK_OFFSETS` order.

    Parameters
    ----------
    mosaic : ndarray
        ``(..., H, W)`` with even H and W.

    Returns
    -------
    ndarray
        ``(..., 4, H/2, W/2)``; :func:`unpack` inverts it.

    Examples
    --------
    >>> import numpy as np
    >>> m = np.arange(16).reshape(4, 4)
    >>> pack(m)[:, 0, 0].tolist()  # the four sites of the top-left 2x2 cell
    [0, 1, 4, 5]
    >>> bool((unpack(pack(m)) == m).all())
    True
    """
    h, w = mosaic.shape[-2:]
    if h % 2 or w % 2:
        raise CfaError(f"pack: mosaic height and width must be even, got {h}x{w}")
    return np.stack([mosaic[..., dy::2, dx::2] for dy, dx in PACK_OFFSETS], axis=-3)


def unpack(packed: np.ndarray) -> np.ndarray:
    """4 x h x w packed planes -> 2h x 2w mosaic (inverse of :func:`pack`)."""
    if packed.shape[-3] != 4:
        raise CfaError(f"unpack: expected 4 packed channels, got shape {packed.shape}")
    h, w = packed.shape[-2:]
    out = np.empty(packed.shape[:-3] + (2 * h, 2 * w), dtype=packed.dtype)
    for k, (dy, dx) in enumerate(PACK_OFFSETS):
        out[..., dy::2, dx::2] = packed[..., k, :, :]
    return out
