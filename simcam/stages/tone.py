"""``tone``: a global tone curve, per channel.

Accepts scene-linear sRGB and display sRGB and keeps the kind: ``filmic`` is meant
for scene-linear input (its output is display-linear, still to be gamma-encoded,
so the kind stays ``linear_srgb``); ``sidd`` is simple-camera-pipeline's curve,
which that pipeline applies to gamma-encoded values (kind ``display``).
"""

from __future__ import annotations

from typing import Literal

from ..colour.display import tone_filmic, tone_smoothstep
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


@register_stage
class Tone(Stage):
    """Tone curve: ``none``, ``sidd`` (3x^2 - 2x^3 on [0, 1]) or ``filmic`` (Hable 2010, ``exposure`` in EV)."""

    type = "tone"
    accepts = frozenset({"linear_srgb", "display"})

    class Params(StageParams):
        curve: Literal["none", "sidd", "filmic"] = "none"
        #: exposure before the filmic curve, in stops (EV); filmic only
        exposure: float = 0.0

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        c = self.params.curve
        if c == "none":
            return frame.evolve(step=self.type)
        data = tone_smoothstep(frame.data) if c == "sidd" else tone_filmic(frame.data, self.params.exposure)
        return frame.evolve(data, step=self.type)
