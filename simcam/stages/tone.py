"""``tone``: exposure and a global tone curve, per channel.

Accepts scene-linear sRGB and display sRGB and keeps the kind: ``filmic`` is meant
for scene-linear input (its output is display-linear, still to be gamma-encoded,
so the kind stays ``linear_srgb``); ``sidd`` is simple-camera-pipeline's curve,
which that pipeline applies to gamma-encoded values (kind ``display``).

``exposure`` (stops, EV) acts for every curve: the input is multiplied by
``2^exposure`` before the curve (for ``filmic`` on top of Hable's exposure bias,
with the white point moving along so that ``white`` still maps to display white).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..colour.display import tone_filmic, tone_smoothstep
from ..errors import StageError
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


@register_stage
class Tone(Stage, type="tone", accepts=frozenset({"linear_srgb", "display"})):
    """Tone curve: ``none``, ``sidd`` (3x^2 - 2x^3 on [0, 1]) or ``filmic`` (Hable 2010); ``exposure`` in EV for all."""

    class Params(StageParams):
        curve: Literal["none", "sidd", "filmic"] = "none"
        #: exposure before the curve, in stops (EV): the input is multiplied by 2^exposure
        exposure: float = 0.0
        #: filmic only: the scene value (before exposure) mapped to display white
        white: float = 1.0

    def check_params(self, p) -> None:
        if not np.isfinite(p.exposure) or abs(p.exposure) > 64:
            raise StageError(f"tone: exposure: expected a finite value in [-64, 64] EV, got {p.exposure}")
        if not (np.isfinite(p.white) and p.white > 0):
            raise StageError(f"tone: white: expected a finite value > 0, got {p.white}")

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        c, ev = self.params.curve, self.params.exposure
        if c == "filmic":
            return frame.evolve(tone_filmic(frame.data, ev, self.params.white), step=self.type)
        if c == "none" and ev == 0.0:
            return frame.evolve(step=self.type)
        data = frame.data
        if ev != 0.0:
            data = (data * np.float32(2.0 ** ev)).astype(np.float32, copy=False)
        if c == "sidd":
            data = tone_smoothstep(data)
        return frame.evolve(data, step=self.type)
