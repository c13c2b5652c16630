"""``camera_to_xyz``: demosaicked camera RGB -> CIE XYZ (D50), DNG 1.6 chapter 6.

The matrix is that of the capture's white (:func:`simcam.colour.dng.camera_to_xyz_d50`),
scaled so that the white at clipping (the neutral with its largest channel at 1)
has Y = 1 (``normalize``, as the Adobe DNG SDK does). If ``meta.white_balance_gains``
is set, the data were already multiplied by those gains, so the matrix is composed
with their inverse: the XYZ is the same as without white balance.

``mode: sidd`` reproduces simple-camera-pipeline instead (compatibility, not
colorimetric): ``inverse(rownorm(ColorMatrix1))`` applied to the data as they are.
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np

from ..colour.dng import (
    DngColorProfile,
    camera_to_xyz_d50,
    check_vector,
    normalise_white_luminance,
    sidd_camera_to_xyz,
    xy_to_camera_neutral,
)
from ..colour.display import apply_matrix
from ..errors import MetadataError, StageError
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage
from .white_balance import capture_neutral


@register_stage
class CameraToXYZ(Stage, type="camera_to_xyz", accepts=frozenset({"camera_rgb"}), produces="xyz"):
    """Camera RGB -> XYZ D50 with the DNG colour matrices of the capture's white.

    ``white``: ``auto`` (the white the data were balanced to, i.e. 1 / meta.white_balance_gains,
    else the as-shot white), ``as_shot`` (AsShotNeutral / AsShotWhiteXY), ``neutral``
    (explicit camera neutral), ``xy`` (explicit CIE 1931 xy).
    """

    class Params(StageParams):
        white: Literal["auto", "as_shot", "neutral", "xy"] = "auto"
        #: camera neutral (R, G, B), stored-value space; with white: neutral
        neutral: Optional[tuple[float, float, float]] = None
        #: white chromaticity (x, y), CIE 1931; with white: xy
        xy: Optional[tuple[float, float]] = None
        #: use ForwardMatrix1/2 when the file has them (DNG 1.6 chapter 6)
        use_forward_matrix: bool = True
        #: scale so the white at clipping maps to Y = 1 (else the specification's raw scale)
        normalize: bool = True
        #: dng: DNG-specification colour; sidd: simple-camera-pipeline compatibility
        mode: Literal["dng", "sidd"] = "dng"

    def check_params(self, p) -> None:
        if (p.white == "neutral") != (p.neutral is not None):
            raise StageError("camera_to_xyz: neutral: expected [r, g, b] exactly when white is 'neutral'")
        if (p.white == "xy") != (p.xy is not None):
            raise StageError("camera_to_xyz: xy: expected [x, y] exactly when white is 'xy'")

    def matrix(self, meta) -> np.ndarray:
        """The 3x3 float64 matrix applied to this stage's input data."""
        p, src = self.params, meta.source or "metadata"
        if p.mode == "sidd":
            if meta.color_matrix1 is None:
                raise MetadataError(f"{src}: ColorMatrix1: missing; expected a 3x3 XYZ->camera matrix")
            return sidd_camera_to_xyz(meta.color_matrix1, src)
        profile = DngColorProfile.from_meta(meta)
        gains = meta.white_balance_gains
        if gains is not None:
            gains = check_vector(gains, "white_balance_gains", src)
        xy = None
        if p.white == "neutral":
            neutral = check_vector(p.neutral, "camera_to_xyz.neutral", src)
        elif p.white == "xy":
            xy = check_vector(p.xy, "camera_to_xyz.xy", src, n=2)
            neutral = xy_to_camera_neutral(profile, xy)
        elif p.white == "auto" and gains is not None:
            neutral = 1.0 / gains
        elif meta.as_shot_neutral is None and meta.as_shot_white_xy is not None:
            xy = check_vector(meta.as_shot_white_xy, "AsShotWhiteXY", src, n=2)
            neutral = xy_to_camera_neutral(profile, xy)
        else:
            neutral = capture_neutral(meta)
        if xy is not None:
            m = camera_to_xyz_d50(profile, xy=xy, use_forward_matrix=p.use_forward_matrix)
        else:
            m = camera_to_xyz_d50(profile, neutral=neutral, use_forward_matrix=p.use_forward_matrix)
        if p.normalize:
            fm = p.use_forward_matrix and profile.has_forward_matrix
            tag = ("ForwardMatrix1/ForwardMatrix2" if profile.dual else "ForwardMatrix1") if fm else profile._cm_tag()
            m = normalise_white_luminance(m, neutral, src, tag)
        if gains is not None:
            m = m @ np.diag(1.0 / gains)
        return m

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        m = self.matrix(frame.meta)
        return frame.evolve(apply_matrix(frame.data, m), kind="xyz", step=self.type)
