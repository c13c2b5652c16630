"""DNG camera colour: from camera-native RGB to CIE XYZ (D50), float64 pure functions.

Implements DNG 1.6.0.0 specification, chapter 6 "Mapping Camera Color Space to CIE
XYZ Space":

* the XYZ -> camera matrix of a white ``xy``:
  ``XYZtoCamera = AB * CC * CM`` where ``CM`` (ColorMatrix) and ``CC``
  (CameraCalibration) are interpolated between the two calibration illuminants
  linearly in inverse CCT (mired), ``AB = diag(AnalogBalance)``;
* "Translating White Balance xy Coordinates to Camera Neutral Coordinates"
  (:func:`xy_to_camera_neutral`) and the fixed-point iteration of "Translating
  Camera Neutral Coordinates to White Balance xy Coordinates"
  (:func:`camera_neutral_to_xy`);
* "Camera to XYZ (D50) Transform" (:func:`camera_to_xyz_d50`): with ForwardMatrix
  ``CameraToXYZ_D50 = FM * D * inverse(AB * CC)``, ``D = inverse(diag(inverse(AB * CC)
  * CameraNeutral))``; without it ``CameraToXYZ_D50 = CA * inverse(XYZtoCamera)``,
  ``CA`` the Bradford adaptation from the white to D50.

Conventions (documented choices where the specification leaves room):

* Missing ColorMatrix1 is an error (:class:`~simcam.errors.MetadataError`); missing
  CameraCalibration is the identity, missing AnalogBalance is ones.
* A profile is *dual-illuminant* only if ColorMatrix2 is present and both
  calibration illuminants have a known CCT that differ. Otherwise set 1 (ColorMatrix1,
  CameraCalibration1, ForwardMatrix1) is used for every white, as the Adobe DNG SDK
  does. Light-source codes 0 (unknown), 255 (other) and any code not in the EXIF
  LightSource table have no CCT.
* The ForwardMatrix path is used when ForwardMatrix1 (single) or both ForwardMatrix1
  and ForwardMatrix2 (dual) are present; otherwise the ColorMatrix path.
* The illuminant order does not matter (ColorMatrix1 may be the warmer or the cooler).
* ForwardMatrix is used as stored. (The Adobe DNG SDK additionally rescales its rows so
  that camera (1, 1, 1) maps exactly to the D50 white; stored matrices are within about
  1e-3 of that, and colour-hdri, the reference of the tests, follows the spec text.)

References: Adobe, *Digital Negative (DNG) Specification* 1.6.0.0 (2021), chapter 6;
Robertson, A. R. (1968), JOSA 58(11), 1528-1535, doi:10.1364/JOSA.58.001528;
Lam, K. M. (1985), Bradford transform (as tabulated in Hunt, *The Reproduction of
Colour*); Kim et al. (2002) US patent 7,024,034 (Planckian-locus cubic fit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import MetadataError
from ..frame import COLOUR_MATRIX_TAGS

#: D50 white of the DNG profile connection space, CIE 1931 2 deg xy (DNG SDK ``D50_xy_coord``).
D50_XY = np.array([0.3457, 0.3585])

#: Bradford cone-response matrix (Lam 1985), XYZ -> sharpened LMS.
BRADFORD = np.array([
    [0.8951, 0.2664, -0.1614],
    [-0.7502, 1.7135, 0.0367],
    [0.0389, -0.0685, 1.0296],
])


@dataclass(frozen=True)
class LightSource:
    """One EXIF LightSource code: name, CCT (K, as the Adobe DNG SDK assigns it), CIE 1931 xy."""

    code: int
    name: str
    cct: float
    xy: tuple[float, float]


def _planck_xy(cct: float) -> tuple[float, float]:
    """CIE 1931 xy of the Planckian locus at ``cct`` K (Kim et al. 2002 cubic fit, 1667-25000 K)."""
    t = float(cct)
    if t <= 4000.0:
        x = -0.2661239e9 / t**3 - 0.2343589e6 / t**2 + 0.8776956e3 / t + 0.179910
    else:
        x = -3.0258469e9 / t**3 + 2.1070379e6 / t**2 + 0.2226347e3 / t + 0.240390
    if t <= 2222.0:
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif t <= 4000.0:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    return (round(x, 5), round(y, 5))


# CIE 15:2004 table T.3 chromaticities of the CIE standard illuminants (2 deg observer).
_A, _B, _C = (0.44757, 0.40745), (0.34842, 0.35161), (0.31006, 0.31616)
_D50, _D55, _D65, _D75 = (0.34567, 0.35850), (0.33242, 0.34743), (0.31271, 0.32902), (0.29902, 0.31485)

def _planckian(code: int, name: str, cct: float) -> LightSource:
    """A light source whose xy is the Planckian locus at its CCT."""
    return LightSource(code, name, cct, _planck_xy(cct))


#: EXIF 2.3 LightSource codes (DNG CalibrationIlluminant values). CCTs are those of the
#: Adobe DNG SDK (``dng_camera_profile::IlluminantToTemperature``); xy is the CIE
#: standard illuminant the code names (or whose CCT the SDK assigns), and for the
#: fluorescent classes and ISO studio tungsten the Planckian locus at that CCT.
LIGHT_SOURCES: dict[int, LightSource] = {ls.code: ls for ls in (
    LightSource(1, "Daylight", 5500.0, _D55),
    _planckian(2, "Fluorescent", 4200.0),
    LightSource(3, "Tungsten (incandescent light)", 2850.0, _A),
    LightSource(4, "Flash", 5500.0, _D55),
    LightSource(9, "Fine weather", 5500.0, _D55),
    LightSource(10, "Cloudy weather", 6500.0, _D65),
    LightSource(11, "Shade", 7500.0, _D75),
    _planckian(12, "Daylight fluorescent (D 5700-7100K)", 6400.0),
    _planckian(13, "Day white fluorescent (N 4600-5400K)", 5000.0),
    _planckian(14, "Cool white fluorescent (W 3900-4500K)", 4200.0),
    _planckian(15, "White fluorescent (WW 3200-3700K)", 3450.0),
    _planckian(16, "Warm white fluorescent (L 2600-3250K)", 2925.0),
    LightSource(17, "Standard light A", 2850.0, _A),
    LightSource(18, "Standard light B", 5500.0, _B),
    LightSource(19, "Standard light C", 6500.0, _C),
    LightSource(20, "D55", 5500.0, _D55),
    LightSource(21, "D65", 6500.0, _D65),
    LightSource(22, "D75", 7500.0, _D75),
    LightSource(23, "D50", 5000.0, _D50),
    _planckian(24, "ISO studio tungsten", 3200.0),
)}


def illuminant_cct(code: int | None) -> float | None:
    """CCT (K) of an EXIF LightSource code; ``None`` for 0 (unknown), 255 (other) or any unlisted code."""
    ls = _light_source(code)
    return None if ls is None else ls.cct


def illuminant_xy(code: int | None) -> np.ndarray | None:
    """CIE 1931 xy of an EXIF LightSource code (see :data:`LIGHT_SOURCES`); ``None`` when unknown."""
    ls = _light_source(code)
    return None if ls is None else np.array(ls.xy, dtype=np.float64)


def _light_source(code) -> LightSource | None:
    try:
        value = float(np.asarray(code, dtype=np.float64).ravel()[0])
    except (TypeError, ValueError, IndexError):
        return None  # absent or not a number: unknown illuminant
    return LIGHT_SOURCES.get(int(value)) if value.is_integer() else None


# -- chromaticity helpers -----------------------------------------------------------

def xy_to_xyz(xy) -> np.ndarray:
    """CIE xy -> XYZ with Y = 1."""
    x, y = (float(v) for v in np.asarray(xy, dtype=np.float64).ravel()[:2])
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def xyz_to_xy(xyz) -> np.ndarray:
    """CIE XYZ -> xy (the sum must be positive)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    s = xyz.sum()
    return np.array([xyz[0] / s, xyz[1] / s])


# Robertson (1968) isotemperature lines: (mired, u, v, slope t), CIE 1960 UCS, as
# tabulated in Wyszecki & Stiles, Color Science (2nd ed.), table 1(3.11).
_ROBERTSON = np.array([
    (0, 0.18006, 0.26352, -0.24341), (10, 0.18066, 0.26589, -0.25479),
    (20, 0.18133, 0.26846, -0.26876), (30, 0.18208, 0.27119, -0.28539),
    (40, 0.18293, 0.27407, -0.30470), (50, 0.18388, 0.27709, -0.32675),
    (60, 0.18494, 0.28021, -0.35156), (70, 0.18611, 0.28342, -0.37915),
    (80, 0.18740, 0.28668, -0.40955), (90, 0.18880, 0.28997, -0.44278),
    (100, 0.19032, 0.29326, -0.47888), (125, 0.19462, 0.30141, -0.58204),
    (150, 0.19962, 0.30921, -0.70471), (175, 0.20525, 0.31647, -0.84901),
    (200, 0.21142, 0.32312, -1.0182), (225, 0.21807, 0.32909, -1.2168),
    (250, 0.22511, 0.33439, -1.4512), (275, 0.23247, 0.33904, -1.7298),
    (300, 0.24010, 0.34308, -2.0637), (325, 0.24792, 0.34655, -2.4681),
    (350, 0.25591, 0.34951, -2.9641), (375, 0.26400, 0.35200, -3.5814),
    (400, 0.27218, 0.35407, -4.3633), (425, 0.28039, 0.35577, -5.3762),
    (450, 0.28863, 0.35714, -6.7262), (475, 0.29685, 0.35823, -8.5955),
    (500, 0.30505, 0.35907, -11.324), (525, 0.31320, 0.35968, -15.628),
    (550, 0.32129, 0.36011, -23.325), (575, 0.32931, 0.36038, -40.770),
    (600, 0.33724, 0.36051, -116.45),
])


def xy_to_cct(xy) -> float:
    """Correlated colour temperature (K) of a CIE 1931 xy by Robertson's (1968) method.

    The point is located between the two adjacent isotemperature lines whose signed
    distances change sign; the reciprocal temperature is interpolated linearly in
    that distance. Range 1667 K (600 mired) .. infinity (0 mired -> ``inf``);
    points beyond the table are clamped to its ends.
    """
    x, y = (float(v) for v in np.asarray(xy, dtype=np.float64).ravel()[:2])
    den = -2.0 * x + 12.0 * y + 3.0
    u, v = 4.0 * x / den, 6.0 * y / den
    last_dt = 0.0
    for i in range(1, len(_ROBERTSON)):
        t = _ROBERTSON[i, 3]
        norm = np.hypot(1.0, t)
        du, dv = 1.0 / norm, t / norm
        dt = -(u - _ROBERTSON[i, 1]) * dv + (v - _ROBERTSON[i, 2]) * du
        if dt <= 0.0 or i == len(_ROBERTSON) - 1:
            dt = -min(dt, 0.0)
            f = 0.0 if i == 1 else dt / (last_dt + dt)
            mired = _ROBERTSON[i - 1, 0] * f + _ROBERTSON[i, 0] * (1.0 - f)
            return float("inf") if mired <= 0.0 else 1.0e6 / mired
        last_dt = dt
    raise AssertionError("unreachable")  # pragma: no cover


def mired_weight(cct: float, cct1: float, cct2: float) -> float:
    """Weight of calibration set 1 for a white of temperature ``cct`` (DNG 1.6 chapter 6).

    Linear in inverse temperature between the two calibration illuminants, clamped:
    1 at or beyond ``cct1``, 0 at or beyond ``cct2``; either order of ``cct1``/``cct2``.
    """
    if cct1 == cct2:
        return 1.0
    inv, inv1, inv2 = 1.0 / cct, 1.0 / cct1, 1.0 / cct2
    g = (inv - inv2) / (inv1 - inv2)
    return float(min(1.0, max(0.0, g)))


def bradford_matrix(xyz_src, xyz_dst) -> np.ndarray:
    """von Kries adaptation in Bradford cone space mapping white ``xyz_src`` to ``xyz_dst`` (3x3)."""
    lms_s = BRADFORD @ np.asarray(xyz_src, dtype=np.float64)
    lms_d = BRADFORD @ np.asarray(xyz_dst, dtype=np.float64)
    return np.linalg.inv(BRADFORD) @ np.diag(lms_d / lms_s) @ BRADFORD


# -- the profile -----------------------------------------------------------------------

_TAG_NAMES = {
    **COLOUR_MATRIX_TAGS,
    "analog_balance": "AnalogBalance", "as_shot_neutral": "AsShotNeutral",
    "as_shot_white_xy": "AsShotWhiteXY",
}


def _fmt(value) -> str:
    arr = np.asarray(value, dtype=np.float64).ravel()
    return "[" + ", ".join(f"{v:.6g}" for v in arr[:9]) + (", ..." if arr.size > 9 else "") + "]"


def check_matrix(value, tag: str, source: str) -> np.ndarray:
    """A 3x3 float64 matrix from a tag value (9 numbers or 3x3), or a one-line MetadataError."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise MetadataError(f"{source}: {tag}: expected 9 numbers (3x3 matrix), got {value!r}") from None
    if arr.size != 9:
        raise MetadataError(f"{source}: {tag}: expected a 3x3 matrix (9 values), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise MetadataError(f"{source}: {tag}: expected finite values, got {_fmt(arr)}")
    return arr.reshape(3, 3)


def check_vector(value, tag: str, source: str, *, n: int = 3, positive: bool = True) -> np.ndarray:
    """A length-``n`` float64 vector (finite, optionally > 0), or a one-line MetadataError."""
    try:
        arr = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise MetadataError(f"{source}: {tag}: expected {n} numbers, got {value!r}") from None
    if arr.size != n:
        raise MetadataError(f"{source}: {tag}: expected {n} values, got {arr.size} ({_fmt(arr)})")
    if not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0)):
        what = "finite positive" if positive else "finite"
        raise MetadataError(f"{source}: {tag}: expected {what} values, got {_fmt(arr)}")
    return arr


def _inv(m: np.ndarray, tag: str, source: str) -> np.ndarray:
    # Relative conditioning test: a matrix this close to singular gives meaningless colour.
    if np.linalg.cond(m) > 1e12:
        raise MetadataError(f"{source}: {tag}: matrix is singular (cannot be inverted), got {_fmt(m)}")
    return np.linalg.inv(m)


@dataclass(frozen=True)
class DngColorProfile:
    """The colour tags of one capture, validated (float64; DNG 1.6 chapter 6).

    Build with :meth:`from_meta`. ``cct1``/``cct2`` are the CCTs (K) of the
    calibration illuminants, ``None`` when unknown; :attr:`dual` tells whether
    matrices are interpolated.
    """

    color_matrix1: np.ndarray
    color_matrix2: np.ndarray | None = None
    camera_calibration1: np.ndarray | None = None
    camera_calibration2: np.ndarray | None = None
    forward_matrix1: np.ndarray | None = None
    forward_matrix2: np.ndarray | None = None
    analog_balance: np.ndarray | None = None
    cct1: float | None = None
    cct2: float | None = None
    source: str = "metadata"

    @classmethod
    def from_meta(cls, meta) -> "DngColorProfile":
        """Validate the colour tags of a :class:`~simcam.frame.CameraMeta`."""
        src = getattr(meta, "source", "") or "metadata"
        if getattr(meta, "color_matrix1", None) is None:
            raise MetadataError(
                f"{src}: ColorMatrix1: missing; expected a 3x3 XYZ->camera matrix (required for colour rendering)")
        mats = {}
        for name in COLOUR_MATRIX_TAGS:
            value = getattr(meta, name, None)
            mats[name] = None if value is None else check_matrix(value, _TAG_NAMES[name], src)
        ab = getattr(meta, "analog_balance", None)
        ab = None if ab is None else check_vector(ab, "AnalogBalance", src)
        return cls(**mats, analog_balance=ab,
                   cct1=illuminant_cct(getattr(meta, "calibration_illuminant1", None)),
                   cct2=illuminant_cct(getattr(meta, "calibration_illuminant2", None)),
                   source=src)

    # -- structure ---------------------------------------------------------------
    @property
    def dual(self) -> bool:
        """Two calibration sets with distinct known temperatures (else set 1 is used everywhere)."""
        return (self.color_matrix2 is not None and self.cct1 is not None and self.cct2 is not None
                and self.cct1 != self.cct2)

    @property
    def has_forward_matrix(self) -> bool:
        if self.dual:
            return self.forward_matrix1 is not None and self.forward_matrix2 is not None
        return self.forward_matrix1 is not None

    @property
    def ab(self) -> np.ndarray:
        """diag(AnalogBalance) (identity when absent)."""
        return np.diag(self.analog_balance) if self.analog_balance is not None else np.eye(3)

    def weight(self, xy) -> float:
        """Weight of calibration set 1 for white ``xy`` (1.0 for a single-illuminant profile)."""
        if not self.dual:
            return 1.0
        return mired_weight(xy_to_cct(xy), self.cct1, self.cct2)  # type: ignore[arg-type]

    def _mix(self, m1, m2, g: float) -> np.ndarray:
        m1 = np.eye(3) if m1 is None else m1
        if not self.dual:
            return m1
        m2 = np.eye(3) if m2 is None else m2
        return g * m1 + (1.0 - g) * m2

    def color_matrix(self, xy) -> np.ndarray:
        """Interpolated ColorMatrix (XYZ -> reference camera) for white ``xy``."""
        return self._mix(self.color_matrix1, self.color_matrix2, self.weight(xy))

    def camera_calibration(self, xy) -> np.ndarray:
        """Interpolated CameraCalibration for white ``xy`` (identity when absent)."""
        return self._mix(self.camera_calibration1, self.camera_calibration2, self.weight(xy))

    def forward_matrix(self, xy) -> np.ndarray | None:
        """Interpolated ForwardMatrix for white ``xy``; ``None`` when the profile has none."""
        if not self.has_forward_matrix:
            return None
        return self._mix(self.forward_matrix1, self.forward_matrix2, self.weight(xy))

    def xyz_to_camera(self, xy) -> np.ndarray:
        """``XYZtoCamera = AB * CC * CM`` for white ``xy`` (DNG 1.6 chapter 6)."""
        return self.ab @ self.camera_calibration(xy) @ self.color_matrix(xy)

    def _cm_tag(self) -> str:
        return "ColorMatrix1/ColorMatrix2" if self.dual else "ColorMatrix1"


# -- white conversions -------------------------------------------------------------------

def xy_to_camera_neutral(profile: DngColorProfile, xy) -> np.ndarray:
    """Camera neutral (stored-value space, normalised so G = 1) of white ``xy`` (DNG 1.6 ch. 6)."""
    neutral = profile.xyz_to_camera(xy) @ xy_to_xyz(xy)
    if not np.all(np.isfinite(neutral)) or np.any(neutral <= 0):
        raise MetadataError(
            f"{profile.source}: {profile._cm_tag()}: white xy {_fmt(xy)} maps to a camera neutral "
            f"{_fmt(neutral)}; expected positive values")
    return neutral / neutral[1]


def camera_neutral_to_xy(profile: DngColorProfile, neutral, *, max_iter: int = 100,
                         tol: float = 1e-12) -> np.ndarray:
    """White xy of a camera neutral by the DNG fixed-point iteration (DNG 1.6 chapter 6).

    Starting from D50, repeat ``xy <- xy(inverse(XYZtoCamera(xy)) * neutral)`` until
    ``|dx| + |dy| < tol``; if it has not converged after ``max_iter`` passes the mean
    of the last two estimates is returned (as the Adobe DNG SDK does).
    """
    neutral = check_vector(neutral, "AsShotNeutral", profile.source)
    xy = D50_XY.copy()
    prev = xy
    for _ in range(max_iter):
        m = _inv(profile.xyz_to_camera(xy), profile._cm_tag(), profile.source)
        xyz = m @ neutral
        if not np.all(np.isfinite(xyz)) or xyz.sum() <= 0 or xyz[1] <= 0:
            raise MetadataError(
                f"{profile.source}: AsShotNeutral: {_fmt(neutral)} maps to XYZ {_fmt(xyz)}; "
                f"expected a neutral of positive luminance")
        prev, xy = xy, xyz_to_xy(xyz)
        if abs(xy[0] - prev[0]) + abs(xy[1] - prev[1]) < tol:
            return xy
    return 0.5 * (xy + prev)


# -- camera -> XYZ D50 -----------------------------------------------------------------------

def camera_to_xyz_d50(profile: DngColorProfile, *, neutral=None, xy=None,
                      use_forward_matrix: bool = True) -> np.ndarray:
    """Camera (stored values, not white-balanced) -> CIE XYZ D50 matrix (DNG 1.6 chapter 6).

    Give the white as a camera ``neutral`` (AsShotNeutral) or as ``xy``
    (AsShotWhiteXY); exactly one. With ForwardMatrix (and ``use_forward_matrix``)::

        ReferenceNeutral = inverse(AB * CC) * CameraNeutral
        D = inverse(diag(ReferenceNeutral))
        CameraToXYZ_D50 = FM * D * inverse(AB * CC)

    otherwise ``CameraToXYZ_D50 = CA * inverse(AB * CC * CM)`` with ``CA`` the
    Bradford adaptation from the white to D50. Scale as in the specification (see
    :func:`normalise_white_luminance`). Returns a float64 3x3 matrix.
    """
    if (neutral is None) == (xy is None):
        raise ValueError("give exactly one of neutral= or xy=")
    if neutral is not None:
        neutral = check_vector(neutral, "AsShotNeutral", profile.source)
        xy = camera_neutral_to_xy(profile, neutral)
    else:
        xy = check_vector(xy, "AsShotWhiteXY", profile.source, n=2)
        if xy.sum() >= 1.0:
            raise MetadataError(f"{profile.source}: AsShotWhiteXY: expected x + y < 1, got {_fmt(xy)}")
        neutral = xy_to_camera_neutral(profile, xy)
    if use_forward_matrix and profile.has_forward_matrix:
        abcc = profile.ab @ profile.camera_calibration(xy)
        abcc_inv = _inv(abcc, "AnalogBalance*CameraCalibration", profile.source)
        ref = abcc_inv @ neutral
        if np.any(ref <= 0):
            raise MetadataError(
                f"{profile.source}: AsShotNeutral: reference neutral {_fmt(ref)}; expected positive values")
        return profile.forward_matrix(xy) @ np.diag(1.0 / ref) @ abcc_inv
    cam_to_xyz = _inv(profile.xyz_to_camera(xy), profile._cm_tag(), profile.source)
    return bradford_matrix(xy_to_xyz(xy), xy_to_xyz(D50_XY)) @ cam_to_xyz


def normalise_white_luminance(matrix, neutral, source: str = "metadata", tag: str = "ColorMatrix1") -> np.ndarray:
    """Scale a camera -> XYZ matrix so the white at clipping maps to Y = 1.

    The white at clipping is the camera neutral scaled so its largest channel is 1
    (the Adobe DNG SDK's convention for both paths). Unit: the result maps
    normalised raw to XYZ with Y = 1 for that white. ``source`` (the file) and ``tag`` (the
    matrix the transform came from) name the culprit in the error.
    """
    neutral = np.asarray(neutral, dtype=np.float64)
    white = neutral / neutral.max()
    y = float((np.asarray(matrix, dtype=np.float64) @ white)[1])
    if not np.isfinite(y) or y <= 0:
        raise MetadataError(f"{source}: {tag}: the camera->XYZ matrix maps the white {_fmt(white)} to "
                            f"Y = {y:.6g}; expected Y > 0")
    return np.asarray(matrix, dtype=np.float64) / y


def sidd_camera_to_xyz(color_matrix1, source: str = "metadata") -> np.ndarray:
    """simple-camera-pipeline's camera -> XYZ matrix (compatibility, *not* DNG-correct).

    ``inverse(CM1 / rowsum(CM1))``: ColorMatrix1 only, each row normalised to sum 1,
    inverted, applied to white-balanced camera RGB (so camera (1, 1, 1) -> XYZ (1, 1, 1)).
    Reference: A. Abdelhamed, simple-camera-pipeline, ``apply_color_space_transform``.
    """
    cm = check_matrix(color_matrix1, "ColorMatrix1", source)
    sums = cm.sum(axis=1, keepdims=True)
    if np.any(np.abs(sums) < 1e-12):
        raise MetadataError(f"{source}: ColorMatrix1: a row sums to 0, cannot row-normalise {_fmt(cm)}")
    return _inv(cm / sums, "ColorMatrix1", source)
