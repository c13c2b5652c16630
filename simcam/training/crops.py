"""Random CFA-aligned crops of a mosaic, without torch (a batch worker that writes a training set
imports only this, not the PyTorch datasets)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..cfa import shift_pattern
from ..errors import DatasetError


def crop_origin(rng: np.random.Generator, shape: tuple[int, int], p2: int, cfa: str, cfa_out: str | None,
                where: Any = "source") -> tuple[int, int]:
    """Random (top, left) of a ``p2`` x ``p2`` mosaic crop whose pattern becomes ``cfa_out``."""
    h, w = shape
    oy, ox = 0, 0
    if cfa_out:
        cands = [(a, b) for a in (0, 1) for b in (0, 1) if shift_pattern(cfa, a, b) == cfa_out]
        if not cands:
            raise DatasetError(f"{where}: CFA {cfa} cannot be cropped to {cfa_out}")
        oy, ox = cands[0]
    if h - oy < p2 or w - ox < p2:
        raise DatasetError(f"{where}: {h}x{w} mosaic is smaller than a {p2}x{p2} patch")
    top = oy + 2 * int(rng.integers((h - oy - p2) // 2 + 1))
    left = ox + 2 * int(rng.integers((w - ox - p2) // 2 + 1))
    return top, left
