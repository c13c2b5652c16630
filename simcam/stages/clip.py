"""``clip`` and ``quantize``: value-range stages for every kind but ``raw_dn``."""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..errors import StageError
from ..frame import SIGNAL_KINDS, RawFrame
from .base import RowOp, Stage, StageParams, register_stage

_NOT_DN = frozenset(k for k in SIGNAL_KINDS if k != "raw_dn")


@register_stage
class Clip(Stage, type="clip", accepts=_NOT_DN):
    """Clamp values to ``[low, high]`` (either bound may be ``null`` for none). float32."""

    class Params(StageParams):
        low: Optional[float] = 0.0
        high: Optional[float] = 1.0

    def check_params(self, p) -> None:
        lo, hi = p.low, p.high
        for name, v in (("low", lo), ("high", hi)):
            if v is not None and not np.isfinite(v):
                raise StageError(f"clip: {name}: expected a finite number or null, got {v}")
        if lo is not None and hi is not None and lo >= hi:
            raise StageError(f"clip: expected low < high, got low={lo}, high={hi}")

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        lo, hi = self.params.low, self.params.high
        if lo is None and hi is None:
            return frame.evolve(step=self.type)
        data = np.clip(frame.data, lo, hi).astype(np.float32, copy=False)
        return frame.evolve(data, step=self.type)

    def row_op(self, frame: RawFrame) -> RowOp | None:
        lo, hi = self.params.low, self.params.high
        if lo is None and hi is None:
            return None

        def fn(src: np.ndarray, dst: np.ndarray, r0: int) -> None:
            np.clip(src, lo, hi, out=dst)  # a float64 input is clipped in float64, then rounded, as in apply

        return RowOp(fn, lambda f, data: f.evolve(data, step=self.type))


@register_stage
class Quantize(Stage, type="quantize", accepts=_NOT_DN):
    """Round to ``2^bits - 1`` steps on [0, 1] (values are clipped to [0, 1] first); stays float32.

    ``out = round(clip(x, 0, 1) * (2^bits - 1)) / (2^bits - 1)`` (round half to even).
    """

    class Params(StageParams):
        bits: int = 8

    def check_params(self, p) -> None:
        if not 1 <= p.bits <= 16:
            raise StageError(f"quantize: bits: expected an integer in 1..16, got {p.bits}")

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        levels = np.float32(2 ** self.params.bits - 1)
        data = np.round(np.clip(frame.data, 0.0, 1.0) * levels) / levels
        return frame.evolve(data.astype(np.float32), step=self.type)
