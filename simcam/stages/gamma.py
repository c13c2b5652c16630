"""``gamma``: encode linear sRGB for display (-> kind ``display``)."""

from __future__ import annotations

from typing import Literal

from ..colour.display import power_encode, srgb_oetf
from ..errors import StageError
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


@register_stage
class Gamma(Stage, type="gamma", accepts=frozenset({"linear_srgb"}), produces="display"):
    """``curve: srgb`` (IEC 61966-2-1 piecewise OETF) or ``power`` (``sign(x)|x|^exponent``)."""

    class Params(StageParams):
        curve: Literal["srgb", "power"] = "srgb"
        #: exponent of the power curve (default 1/2.2); power only
        exponent: float = 1.0 / 2.2

    def check_params(self, p) -> None:
        if not (0.0 < p.exponent < 10.0):
            raise StageError(f"gamma: exponent: expected a value in (0, 10), got {p.exponent}")

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        if self.params.curve == "srgb":
            data = srgb_oetf(frame.data)
        else:
            data = power_encode(frame.data, self.params.exponent)
        return frame.evolve(data, kind="display", step=self.type)
