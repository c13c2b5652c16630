"""``xyz_to_srgb``: CIE XYZ (D50) -> scene-linear sRGB (D65), IEC 61966-2-1. Linear, float32, no clip."""

from __future__ import annotations

from typing import Literal

from ..colour.display import apply_matrix, sidd_xyz_to_srgb_matrix, xyz_d50_to_linear_srgb_matrix
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


@register_stage
class XYZToSRGB(Stage, type="xyz_to_srgb", accepts=frozenset({"xyz"}), produces="linear_srgb"):
    """Bradford D50 -> D65, then the IEC 61966-2-1 XYZ -> linear sRGB matrix.

    ``mode: sidd`` uses simple-camera-pipeline's row-normalised matrix without
    adaptation instead (compatibility only).
    """

    class Params(StageParams):
        mode: Literal["standard", "sidd"] = "standard"

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        m = sidd_xyz_to_srgb_matrix() if self.params.mode == "sidd" else xyz_d50_to_linear_srgb_matrix()
        return frame.evolve(apply_matrix(frame.data, m), kind="linear_srgb", step=self.type)
