"""``dcp``: render camera RGB with a DNG camera profile, as Adobe-style converters do.

Demosaicked camera RGB (white-balanced or not) -> XYZ (D50) through the whole camera-profile
model of the DNG Specification 1.7.0.0: the profile's ColorMatrix/ForwardMatrix for the
capture's white (chapter 6, "Camera to XYZ (D50) Transform"), then in linear ProPhoto RGB the
HueSatMap (ProfileHueSatMapData1/2 interpolated with the matrices' CCT weight), the exposure
ramp (BaselineExposure + BaselineExposureOffset, DefaultBlackRender), the LookTable and the
tone curve (ProfileToneCurve), in the order of the Adobe DNG SDK's reference renderer (see
:mod:`simcam.colour.dcp` for each step and where simcam deviates). The output is XYZ (D50)
of the *rendered* image (display-referred, white Y = 1): follow it with ``xyz_to_srgb``,
``clip`` and ``gamma`` (pipeline ``srgb-dcp``).

Profile sources: ``embedded`` — the DNG's own colour tags (CameraMeta) and its profile tags
(``meta.extra["camera_profile"]``, read by :mod:`simcam.io.dcp`; a DNG without them renders with
its matrices only); ``file`` — a ``.dcp`` file (``path``), read when the stage is built, whose
matrices replace the DNG's (the DNG's AnalogBalance is kept; its CameraCalibration is used only
when its CameraCalibrationSignature equals the profile's ProfileCalibrationSignature, as the
DNG SDK decides); ``auto`` (default) — ``file`` when ``path`` is given, else ``embedded``.

Choices (documented, not in the specification):

* No tone curve in the profile: no curve. Adobe Camera Raw then applies its own default
  curve ("ACR 3" curve), which is a table of Adobe's and not part of the DNG specification,
  so simcam does not reproduce it (set ``apply_tone_curve: false`` for a linear render anyway).
* ``shadows`` is Camera Raw's Blacks/Shadows setting (black point ``shadows / 1000`` of white);
  left unset it is 5 (Camera Raw's default) when DefaultBlackRender is 0 (Auto) and 0 when it
  is 1 (None). ShadowScale is taken as 1.
* ForwardMatrix rows are scaled so that camera (1, 1, 1) maps exactly to the D50 white, as the
  DNG SDK does (``NormalizeForwardMatrix``; stored matrices are within ~1e-3 of it).
* The profile's UniqueCameraModel is not compared with the DNG's.
* Triple-illuminant profiles (DNG 1.6: ColorMatrix3, ...) are refused.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal, Optional

import numpy as np

from ..colour.dcp import (
    PROPHOTO_TO_XYZ_D50,
    XYZ_D50_TO_PROPHOTO,
    apply_hsv_table,
    exposure_ramp,
    mix_tables,
    rgb_tone,
    spline_table,
)
from ..colour.dng import (
    D50_XY,
    DngColorProfile,
    camera_neutral_to_xy,
    camera_to_xyz_d50,
    check_matrix,
    check_vector,
    illuminant_cct,
    mired_weight,
    normalise_white_luminance,
    xy_to_camera_neutral,
    xy_to_cct,
    xy_to_xyz,
)
from ..errors import MetadataError, StageError
from ..frame import RawFrame
from ..io.dcp import CameraProfile, read_dcp
from ..parallel import run_bands
from .base import Stage, StageParams, register_stage
from .white_balance import capture_neutral

#: Camera Raw's default Shadows (Blacks) setting, used when DefaultBlackRender is Auto.
ACR_DEFAULT_SHADOWS = 5.0
#: Pixels per band of the parallel pass.
_BAND_PIXELS = 1 << 17


def normalize_forward_matrix(fm: np.ndarray) -> np.ndarray:
    """Scale each row of a ForwardMatrix so that camera (1, 1, 1) maps to the D50 white (DNG SDK)."""
    fm = np.asarray(fm, dtype=np.float64)
    xyz = fm @ np.ones(3)
    if np.any(np.abs(xyz) < 1e-12):
        return fm
    return np.diag(xy_to_xyz(D50_XY) / xyz) @ fm


@dataclasses.dataclass(frozen=True)
class DcpRender:
    """Everything the pixel pass needs, computed from the profile and the frame's metadata."""

    matrix: np.ndarray  # 3x3: stage input -> linear ProPhoto RGB
    clip: np.ndarray  # per-channel camera-white clip of the input
    white_xy: np.ndarray
    weight1: float  # weight of calibration set 1 (matrices and HueSatMap)
    hue_sat_map: np.ndarray | None
    hue_sat_encoding: int
    exposure: float  # total EV of the ramp / darkening curve
    black: float  # black point of the ramp (fraction of white)
    look_table: np.ndarray | None
    look_encoding: int
    tone_table: np.ndarray | None


@register_stage
class Dcp(Stage, type="dcp", accepts=frozenset({"camera_rgb"}), produces="xyz"):
    """Camera RGB -> XYZ (D50) through a DNG camera profile (matrices, HueSatMap, exposure, LookTable, tone curve)."""

    class Params(StageParams):
        #: auto: a .dcp file when ``path`` is set, else the DNG's embedded profile
        source: Literal["auto", "embedded", "file"] = "auto"
        #: the .dcp file (source file / auto)
        path: Optional[str] = None
        apply_hue_sat_map: bool = True
        apply_look_table: bool = True
        #: the profile's ProfileToneCurve (none when the profile has no curve)
        apply_tone_curve: bool = True
        #: add BaselineExposure (DNG) + BaselineExposureOffset (profile) to ``exposure``
        baseline_exposure: bool = True
        #: user exposure, EV (Camera Raw's Exposure)
        exposure: float = 0.0
        #: black point in thousandths of white (Camera Raw's Shadows); null: from DefaultBlackRender
        shadows: Optional[float] = None
        #: use ForwardMatrix1/2 when the profile has them
        use_forward_matrix: bool = True

    def check_params(self, p) -> None:
        if p.source == "file" and not p.path:
            raise StageError("dcp: path: expected the .dcp file to read when source is 'file'")
        if p.source == "embedded" and p.path:
            raise StageError(f"dcp: path: {p.path!r} given with source 'embedded'; expected no path "
                             f"(or source: file)")
        if not np.isfinite(p.exposure) or abs(p.exposure) > 16:
            raise StageError(f"dcp: exposure: expected a finite value in [-16, 16] EV, got {p.exposure}")
        if p.shadows is not None and not (np.isfinite(p.shadows) and 0.0 <= p.shadows <= 100.0):
            raise StageError(f"dcp: shadows: expected a value in [0, 100] (or null), got {p.shadows}")
        self._file_profile = read_dcp(Path(p.path)) if self.uses_file else None
        if self._file_profile is not None and self._file_profile.third_illuminant:
            raise StageError(f"dcp: {p.path}: a triple-illuminant profile (ColorMatrix3, DNG 1.6); "
                             f"expected one or two calibration illuminants")

    @property
    def uses_file(self) -> bool:
        return self.params.source == "file" or (self.params.source == "auto" and bool(self.params.path))

    # -- the profile -----------------------------------------------------------------------------
    def camera_profile(self, meta) -> CameraProfile | None:
        """The profile tags in use: the .dcp file's, or the DNG's embedded ones (None when it has none)."""
        if self._file_profile is not None:
            return self._file_profile
        prof = (meta.extra or {}).get("camera_profile") if isinstance(meta.extra, dict) else None
        if prof is not None and not isinstance(prof, CameraProfile):
            raise MetadataError(f"{meta.source or 'metadata'}: camera_profile: expected a CameraProfile, "
                                f"got {type(prof).__name__}")
        if prof is not None and prof.third_illuminant:
            raise MetadataError(f"{meta.source or 'metadata'}: ColorMatrix3: a triple-illuminant profile "
                                f"(DNG 1.6); expected one or two calibration illuminants")
        return prof

    def colour_profile(self, meta, prof: CameraProfile | None) -> DngColorProfile:
        """The matrices (DNG 1.7.0.0 ch. 6) of the profile in use, ForwardMatrix rows normalised."""
        src = meta.source or "metadata"
        embedded_sig = getattr((meta.extra or {}).get("camera_profile"), "camera_calibration_signature", "")
        if self._file_profile is None:
            colour = DngColorProfile.from_meta(meta)
            use_cc = prof is None or (prof.camera_calibration_signature or "") == (prof.calibration_signature or "")
            if not use_cc:
                colour = dataclasses.replace(colour, camera_calibration1=None, camera_calibration2=None)
        else:
            fp = self._file_profile
            use_cc = (embedded_sig or "") == (fp.calibration_signature or "")
            cc = {}
            for k in (1, 2):
                v = getattr(meta, f"camera_calibration{k}", None) if use_cc else None
                cc[f"camera_calibration{k}"] = None if v is None else check_matrix(v, f"CameraCalibration{k}", src)
            ab = meta.analog_balance
            colour = DngColorProfile(
                color_matrix1=fp.color_matrix1, color_matrix2=fp.color_matrix2,
                forward_matrix1=fp.forward_matrix1, forward_matrix2=fp.forward_matrix2,
                analog_balance=None if ab is None else check_vector(ab, "AnalogBalance", src),
                cct1=illuminant_cct(fp.calibration_illuminant1), cct2=illuminant_cct(fp.calibration_illuminant2),
                source=fp.source, **cc)
        if not self.params.use_forward_matrix:
            return dataclasses.replace(colour, forward_matrix1=None, forward_matrix2=None)
        fms = {k: normalize_forward_matrix(getattr(colour, k)) for k in ("forward_matrix1", "forward_matrix2")
               if getattr(colour, k) is not None}
        return dataclasses.replace(colour, **fms)

    def plan(self, meta) -> DcpRender:
        """Matrix, clip, table weights and curves for a frame with metadata ``meta``."""
        p, src = self.params, meta.source or "metadata"
        prof = self.camera_profile(meta)
        colour = self.colour_profile(meta, prof)
        gains = meta.white_balance_gains
        if gains is not None:
            gains = check_vector(gains, "white_balance_gains", src)
            neutral = 1.0 / gains
        elif meta.as_shot_neutral is None and meta.as_shot_white_xy is not None:
            neutral = xy_to_camera_neutral(colour, check_vector(meta.as_shot_white_xy, "AsShotWhiteXY", src, n=2))
        else:
            neutral = capture_neutral(meta)
        xy = camera_neutral_to_xy(colour, neutral)
        cam_to_xyz = normalise_white_luminance(camera_to_xyz_d50(colour, neutral=neutral), neutral)
        camera_white = neutral / neutral.max()
        clip = camera_white if gains is None else camera_white * gains
        if gains is not None:
            cam_to_xyz = cam_to_xyz @ np.diag(1.0 / gains)

        hsm = enc = None
        weight1 = colour.weight(xy)
        if prof is not None and p.apply_hue_sat_map and prof.hue_sat_map1 is not None:
            t1, t2 = prof.hue_sat_map1, prof.hue_sat_map2
            cct1, cct2 = colour.cct1, colour.cct2  # the profile's calibration illuminants
            w = 1.0
            if t2 is not None and cct1 is not None and cct2 is not None and cct1 != cct2:
                w = mired_weight(xy_to_cct(xy), cct1, cct2)
            hsm = mix_tables(t1.data, None if t2 is None else t2.data, w)
            enc = t1.encoding
        exposure = float(p.exposure)
        if p.baseline_exposure:
            exposure += float(getattr(meta, "baseline_exposure", 0.0) or 0.0)
            exposure += prof.baseline_exposure_offset if prof is not None else 0.0
        shadows = p.shadows
        if shadows is None:
            black_none = prof is not None and prof.default_black_render == 1
            shadows = 0.0 if black_none else ACR_DEFAULT_SHADOWS
        look = prof.look_table if (prof is not None and p.apply_look_table) else None
        curve = prof.tone_curve if (prof is not None and p.apply_tone_curve) else None
        return DcpRender(
            matrix=XYZ_D50_TO_PROPHOTO @ cam_to_xyz, clip=clip, white_xy=xy, weight1=weight1,
            hue_sat_map=hsm, hue_sat_encoding=enc or 0, exposure=exposure, black=shadows * 0.001,
            look_table=None if look is None else look.data, look_encoding=0 if look is None else look.encoding,
            tone_table=spline_table(curve, exposure))

    # -- pixels ------------------------------------------------------------------------------------
    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        plan = self.plan(frame.meta)
        out = render_prophoto_to_xyz(frame.data, plan)
        prof = self.camera_profile(frame.meta)
        name = (prof.name or Path(prof.source).name) if prof is not None else "matrices only"
        return frame.evolve(out, kind="xyz", step=f"{self.type}({name})")


def _mix3(m: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, i: int) -> np.ndarray:
    """Row ``i`` of the 3x3 ``m`` applied to channels (a, b, c): no BLAS call on a tiny matrix per band."""
    return m[i, 0] * a + m[i, 1] * b + m[i, 2] * c


def render_prophoto_to_xyz(data: np.ndarray, plan: DcpRender) -> np.ndarray:
    """The pixel pass of :class:`Dcp`: H x W x 3 stage input -> H x W x 3 XYZ (D50), float32, on row bands."""
    h, w = data.shape[:2]
    out = np.empty((h, w, 3), dtype=np.float32)
    m = plan.matrix.astype(np.float32)
    to_xyz = PROPHOTO_TO_XYZ_D50.astype(np.float32)
    clip = [np.float32(c) for c in plan.clip]
    zero, one = np.float32(0.0), np.float32(1.0)
    rows = max(1, _BAND_PIXELS // max(w, 1))

    def band(r0: int, r1: int) -> None:
        x = data[r0:r1].reshape(-1, 3)
        cam = [np.minimum(x[:, k], clip[k]) for k in range(3)]  # clip at the camera white
        r, g, b = (np.clip(_mix3(m, *cam, i), zero, one) for i in range(3))  # linear ProPhoto RGB in [0, 1]
        if plan.hue_sat_map is not None:
            r, g, b = apply_hsv_table(r, g, b, plan.hue_sat_map, plan.hue_sat_encoding)
        if plan.exposure != 0.0 or plan.black != 0.0:
            r, g, b = (exposure_ramp(c, plan.exposure, plan.black) for c in (r, g, b))
        if plan.look_table is not None:
            r, g, b = apply_hsv_table(r, g, b, plan.look_table, plan.look_encoding)
        if plan.tone_table is not None:
            r, g, b = rgb_tone(r, g, b, plan.tone_table)
        dst = out[r0:r1].reshape(-1, 3)
        for i in range(3):
            dst[:, i] = _mix3(to_xyz, r, g, b, i)

    run_bands(h, band, rows=rows)
    return out
