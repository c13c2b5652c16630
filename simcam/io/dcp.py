"""DNG camera profiles: read ``.dcp`` files and the profile tags embedded in a DNG.

A DNG Camera Profile file (``.dcp``) is a TIFF-like file holding one IFD of the
camera-profile tags of the DNG Specification 1.7.0.0, chapter 4 ("DNG Tags"): the
header is ``II`` + 0x4352 ("IIRC", little-endian) or ``MM`` + 0x4352 ("MMCR",
big-endian) followed by the uint32 offset of that IFD; entries are the usual
TIFF 12-byte (tag, type, count, value-or-offset) records. :func:`read_dcp` parses
such a file with its own small reader (no TIFF library: a DCP has no image data)
and validates every tag it uses; :func:`embedded_profile_extra` reads the same tags
from IFD 0 of a DNG opened with tifffile (``simcam.io.dng`` stores the result as
``meta.extra["camera_profile"]``).

Tags read (DNG 1.7.0.0, chapter 4): UniqueCameraModel, ColorMatrix1/2,
ForwardMatrix1/2, CalibrationIlluminant1/2, ProfileName, ProfileCalibrationSignature,
ProfileHueSatMapDims, ProfileHueSatMapData1/2, ProfileHueSatMapEncoding,
ProfileLookTableDims, ProfileLookTableData, ProfileLookTableEncoding,
ProfileToneCurve, ProfileEmbedPolicy, ProfileCopyright, BaselineExposureOffset,
DefaultBlackRender; from a DNG also CameraCalibrationSignature. The third
calibration set of DNG 1.6 (CalibrationIlluminant3, ColorMatrix3, ForwardMatrix3,
ProfileHueSatMapData3) is recorded as present (:attr:`CameraProfile.third_illuminant`)
but not read.

Every malformed value is a one-line :class:`~simcam.errors.DngError` naming the
file, the tag, what it holds and what was expected.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import DngError
from ..frame import COLOUR_MATRIX_TAGS

#: Camera-profile tag codes (DNG Specification 1.7.0.0, chapter 4).
PROFILE_TAGS: dict[str, int] = {
    "UniqueCameraModel": 50708, "ColorMatrix1": 50721, "ColorMatrix2": 50722,
    "CalibrationIlluminant1": 50778, "CalibrationIlluminant2": 50779,
    "CameraCalibrationSignature": 50931, "ProfileCalibrationSignature": 50932,
    "ProfileName": 50936, "ProfileHueSatMapDims": 50937, "ProfileHueSatMapData1": 50938,
    "ProfileHueSatMapData2": 50939, "ProfileToneCurve": 50940, "ProfileEmbedPolicy": 50941,
    "ProfileCopyright": 50942, "ForwardMatrix1": 50964, "ForwardMatrix2": 50965,
    "ProfileLookTableDims": 50981, "ProfileLookTableData": 50982,
    "ProfileHueSatMapEncoding": 51107, "ProfileLookTableEncoding": 51108,
    "BaselineExposureOffset": 51109, "DefaultBlackRender": 51110,
    "CalibrationIlluminant3": 52529, "ColorMatrix3": 52531, "ForwardMatrix3": 52532,
    "ProfileHueSatMapData3": 52537,
}
_NAMES = {v: k for k, v in PROFILE_TAGS.items()}

#: The DCP magic numbers: byte order + 0x4352 ("RC" read little-endian).
DCP_MAGIC = {b"IIRC": "<", b"MMCR": ">"}

# TIFF field types: (struct code, size in bytes).
_TYPES = {1: ("B", 1), 2: ("s", 1), 3: ("H", 2), 4: ("I", 4), 5: ("I", 8), 6: ("b", 1), 7: ("B", 1),
          8: ("h", 2), 9: ("i", 4), 10: ("i", 8), 11: ("f", 4), 12: ("d", 8)}
_TYPE_NAMES = {1: "BYTE", 2: "ASCII", 3: "SHORT", 4: "LONG", 5: "RATIONAL", 6: "SBYTE", 7: "UNDEFINED",
               8: "SSHORT", 9: "SLONG", 10: "SRATIONAL", 11: "FLOAT", 12: "DOUBLE"}
_INTEGER = (1, 3, 4, 8, 9)
_REAL = (5, 10, 11, 12)
_FLOAT_TABLE = (11, 12)  # tables are FLOAT in the specification; DOUBLE is accepted
#: Largest HueSatMap / LookTable (entries, i.e. hue x sat x value divisions) accepted.
MAX_TABLE_ENTRIES = 1 << 22
#: Largest .dcp file read (bytes).
MAX_DCP_BYTES = 256 << 20


@dataclass(frozen=True)
class HueSatTable:
    """One hue/saturation/value mapping table (ProfileHueSatMapData or ProfileLookTableData).

    ``data`` is float32 of shape (value divisions, hue divisions, saturation divisions, 3),
    the storage order of the specification (value outer, hue middle, saturation inner);
    the last axis holds (hue shift in degrees, saturation scale, value scale).
    ``encoding`` is 0 (linear) or 1 (sRGB) for the value axis (ProfileHueSatMapEncoding /
    ProfileLookTableEncoding).
    """

    data: np.ndarray
    encoding: int = 0

    @property
    def dims(self) -> tuple[int, int, int]:
        """(hue, saturation, value) divisions, the order of the *Dims tags."""
        v, h, s, _ = self.data.shape
        return int(h), int(s), int(v)

    def is_identity(self, tol: float = 0.0) -> bool:
        d = self.data
        return bool(np.all(np.abs(d[..., 0]) <= tol) and np.all(np.abs(d[..., 1:] - 1.0) <= tol))


@dataclass(frozen=True)
class CameraProfile:
    """The camera-profile tags of a ``.dcp`` file or of a DNG's IFD 0 (validated).

    Matrices are float64 3x3 (None when absent); ``hue_sat_map1/2`` and ``look_table``
    are :class:`HueSatTable`; ``tone_curve`` is float64 (n, 2) of (input, output) pairs
    from (0, 0) to (1, 1). Immutable (arrays read-only), so a copy of the metadata shares it.
    """

    source: str = ""
    name: str = ""
    copyright: str = ""
    unique_camera_model: str = ""
    calibration_signature: str = ""  # ProfileCalibrationSignature
    camera_calibration_signature: str = ""  # CameraCalibrationSignature (a DNG tag, read with an embedded profile)
    embed_policy: int | None = None
    color_matrix1: np.ndarray | None = None
    color_matrix2: np.ndarray | None = None
    forward_matrix1: np.ndarray | None = None
    forward_matrix2: np.ndarray | None = None
    calibration_illuminant1: int | None = None
    calibration_illuminant2: int | None = None
    hue_sat_map1: HueSatTable | None = None
    hue_sat_map2: HueSatTable | None = None
    look_table: HueSatTable | None = None
    tone_curve: np.ndarray | None = None
    baseline_exposure_offset: float = 0.0
    default_black_render: int = 0  # 0 = Auto, 1 = None
    third_illuminant: bool = False

    def __deepcopy__(self, memo) -> "CameraProfile":
        return self  # immutable

    def summary(self) -> dict[str, Any]:
        """A short JSON-friendly description (table dimensions, not their values)."""
        out: dict[str, Any] = {"source": self.source, "name": self.name}
        for key in ("hue_sat_map1", "hue_sat_map2", "look_table"):
            t = getattr(self, key)
            if t is not None:
                out[key] = {"dims": list(t.dims), "encoding": "sRGB" if t.encoding else "linear"}
        if self.tone_curve is not None:
            out["tone_curve_points"] = int(self.tone_curve.shape[0])
        for key in ("baseline_exposure_offset", "default_black_render", "calibration_illuminant1",
                    "calibration_illuminant2", "embed_policy"):
            v = getattr(self, key)
            if v is not None:
                out[key] = v
        out["matrices"] = [f.name for f in fields(self) if f.name.endswith(("matrix1", "matrix2"))
                           and getattr(self, f.name) is not None]
        return out

    def __str__(self) -> str:  # what `simcam info` prints for meta.extra["camera_profile"]
        s = self.summary()
        parts = [f"{k}={v}" for k, v in s.items() if k != "source" and v not in ("", [], None)]
        return "CameraProfile(" + ", ".join(parts) + ")"

    __repr__ = __str__


# ---------------------------------------------------------------------------------------------
# tag values
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Entry:
    """One decoded IFD entry: TIFF type code, count and value (float64 array, or str for ASCII)."""

    type: int
    count: int
    value: Any


class _TagSource:
    """Lookup of decoded entries by tag name, with the file for error messages."""

    def __init__(self, where: str, entries: dict[int, _Entry]):
        self.where, self.entries = where, entries

    def has(self, name: str) -> bool:
        return PROFILE_TAGS[name] in self.entries

    def err(self, name: str, msg: str) -> DngError:
        return DngError(f"{self.where}: {name}: {msg}")

    def _get(self, name: str, allowed: tuple[int, ...]) -> _Entry | None:
        e = self.entries.get(PROFILE_TAGS[name])
        if e is None:
            return None
        if e.type not in allowed:
            want = "/".join(_TYPE_NAMES[t] for t in allowed)
            raise self.err(name, f"type {_TYPE_NAMES.get(e.type, e.type)}; expected {want}")
        return e

    def text(self, name: str) -> str:
        e = self._get(name, (2, 1, 7))
        if e is None:
            return ""
        v = e.value
        if not isinstance(v, str):
            v = bytes(np.asarray(v, dtype=np.uint8)).decode("latin-1")
        return v.split("\0", 1)[0].strip()

    def numbers(self, name: str, allowed: tuple[int, ...], count: int | None = None) -> np.ndarray | None:
        e = self._get(name, allowed)
        if e is None:
            return None
        v = np.asarray(e.value, dtype=np.float64).ravel()
        if count is not None and v.size != count:
            raise self.err(name, f"{v.size} values; expected {count}")
        if not np.all(np.isfinite(v)):
            raise self.err(name, "non-finite value (NaN or infinity); expected finite numbers")
        return v

    def integer(self, name: str, choices: tuple[int, ...] | None = None) -> int | None:
        v = self.numbers(name, _INTEGER, 1)
        if v is None:
            return None
        i = int(v[0])
        if choices is not None and i not in choices:
            raise self.err(name, f"{i}; expected one of {', '.join(map(str, choices))}")
        return i

    def matrix(self, name: str) -> np.ndarray | None:
        v = self.numbers(name, _REAL)
        if v is None:
            return None
        if v.size != 9:
            raise self.err(name, f"{v.size} values; expected 9 (a 3x3 matrix: simcam renders 3-colour cameras)")
        m = v.reshape(3, 3)
        m.setflags(write=False)
        return m


def _table(src: _TagSource, dims_name: str, data_names: tuple[str, ...], enc_name: str):
    """The tables of one Dims tag (HueSatMap: Data1/Data2; LookTable: Data), validated."""
    present = [n for n in data_names if src.has(n)]
    dims = src.numbers(dims_name, (3, 4), 3)
    if dims is None:
        if present:
            raise src.err(present[0], f"present without {dims_name}; expected both tags")
        if src.has(enc_name):
            src.integer(enc_name, (0, 1))
        return [None] * len(data_names)
    h, s, v = (int(x) for x in dims)
    if h < 1 or s < 2 or v < 1:
        raise src.err(dims_name, f"[{h}, {s}, {v}]; expected hue divisions >= 1, saturation divisions >= 2, "
                                 f"value divisions >= 1")
    if h * s * v > MAX_TABLE_ENTRIES:
        raise src.err(dims_name, f"[{h}, {s}, {v}] = {h * s * v} entries; expected at most {MAX_TABLE_ENTRIES}")
    if not src.has(data_names[0]):
        raise src.err(data_names[0], f"missing although {dims_name} is present; expected {h}x{s}x{v}x3 floats")
    encoding = src.integer(enc_name, (0, 1)) or 0
    out = []
    for name in data_names:
        raw = src.numbers(name, _FLOAT_TABLE)
        if raw is None:
            out.append(None)
            continue
        if raw.size != h * s * v * 3:
            raise src.err(name, f"{raw.size} values; expected {h}x{s}x{v}x3 = {h * s * v * 3} "
                                f"({dims_name} = [{h}, {s}, {v}])")
        data = raw.astype(np.float32).reshape(v, h, s, 3)
        bad = (data[..., 1] < 0) | (data[..., 2] < 0)
        if np.any(bad):
            k = int(np.flatnonzero(bad.ravel())[0])
            raise src.err(name, f"entry {k} has a negative saturation or value scale "
                                f"({data.reshape(-1, 3)[k].tolist()}); expected scales >= 0")
        data.setflags(write=False)
        out.append(HueSatTable(data, encoding))
    return out


def _tone_curve(src: _TagSource) -> np.ndarray | None:
    v = src.numbers("ProfileToneCurve", _FLOAT_TABLE)
    if v is None:
        return None
    if v.size < 4 or v.size % 2:
        raise src.err("ProfileToneCurve", f"{v.size} values; expected an even number >= 4 (input, output pairs)")
    pts = v.reshape(-1, 2)
    x, y = pts[:, 0], pts[:, 1]
    if np.any(x < 0) or np.any(x > 1) or np.any(y < 0) or np.any(y > 1):
        raise src.err("ProfileToneCurve", "a point lies outside [0, 1] x [0, 1]; expected values in [0, 1]")
    if np.any(np.diff(x) <= 0):
        k = int(np.flatnonzero(np.diff(x) <= 0)[0])
        raise src.err("ProfileToneCurve", f"inputs not strictly increasing at point {k + 1} "
                                          f"({x[k]:.6g} then {x[k + 1]:.6g}); expected increasing inputs")
    tol = 1e-6
    if abs(x[0]) > tol or abs(y[0]) > tol or abs(x[-1] - 1) > tol or abs(y[-1] - 1) > tol:
        raise src.err("ProfileToneCurve", f"runs from ({x[0]:.6g}, {y[0]:.6g}) to ({x[-1]:.6g}, {y[-1]:.6g}); "
                                          f"expected (0, 0) to (1, 1)")
    pts = pts.copy()
    pts.setflags(write=False)
    return pts


def _illuminant(src: _TagSource, name: str) -> int | None:
    v = src.numbers(name, _INTEGER, 1)
    if v is None:
        return None
    i = int(v[0])
    if not 0 <= i <= 65535:
        raise src.err(name, f"{i}; expected an EXIF LightSource code (0..65535)")
    return i


def _profile(src: _TagSource, *, require_color_matrix: bool) -> CameraProfile:
    if require_color_matrix and not src.has("ColorMatrix1"):
        raise src.err("ColorMatrix1", "missing; expected a 3x3 XYZ->camera matrix (required in a camera profile)")
    hsm1, hsm2 = _table(src, "ProfileHueSatMapDims", ("ProfileHueSatMapData1", "ProfileHueSatMapData2"),
                        "ProfileHueSatMapEncoding")
    (look,) = _table(src, "ProfileLookTableDims", ("ProfileLookTableData",), "ProfileLookTableEncoding")
    beo = src.numbers("BaselineExposureOffset", _REAL, 1)
    if beo is not None and abs(beo[0]) > 64:
        raise src.err("BaselineExposureOffset", f"{beo[0]:.6g} EV; expected a value in [-64, 64]")
    return CameraProfile(
        source=src.where,
        name=src.text("ProfileName"),
        copyright=src.text("ProfileCopyright"),
        unique_camera_model=src.text("UniqueCameraModel"),
        calibration_signature=src.text("ProfileCalibrationSignature"),
        camera_calibration_signature=src.text("CameraCalibrationSignature"),
        embed_policy=src.integer("ProfileEmbedPolicy"),
        **{name: src.matrix(tag) for name, tag in COLOUR_MATRIX_TAGS.items()
           if not name.startswith("camera_calibration")},  # a camera profile holds no CameraCalibration
        calibration_illuminant1=_illuminant(src, "CalibrationIlluminant1"),
        calibration_illuminant2=_illuminant(src, "CalibrationIlluminant2"),
        hue_sat_map1=hsm1,
        hue_sat_map2=hsm2,
        look_table=look,
        tone_curve=_tone_curve(src),
        baseline_exposure_offset=0.0 if beo is None else float(beo[0]),
        default_black_render=src.integer("DefaultBlackRender", (0, 1)) or 0,
        third_illuminant=any(src.has(n) for n in ("CalibrationIlluminant3", "ColorMatrix3", "ForwardMatrix3",
                                                  "ProfileHueSatMapData3")),
    )


# ---------------------------------------------------------------------------------------------
# .dcp files
# ---------------------------------------------------------------------------------------------

def _decode(where: str, data: bytes, order: str, code: int, typ: int, count: int, field: bytes) -> _Entry:
    name = _NAMES.get(code, str(code))
    fmt, size = _TYPES[typ]
    nbytes = count * size
    if nbytes <= 4:
        raw = field[:nbytes]
    else:
        (offset,) = struct.unpack(order + "I", field)
        if offset + nbytes > len(data):
            raise DngError(f"{where}: {name}: {count} {_TYPE_NAMES[typ]} values at byte {offset} run past the "
                           f"end of the file ({len(data)} bytes); expected them inside it (truncated file?)")
        raw = data[offset:offset + nbytes]
    if typ == 2:
        return _Entry(typ, count, raw.decode("latin-1"))
    if typ in (5, 10):
        pairs = np.frombuffer(raw, dtype=np.dtype(order + ("u4" if typ == 5 else "i4"))).astype(np.float64)
        num, den = pairs[0::2], pairs[1::2]
        if np.any((den == 0) & (num != 0)):
            raise DngError(f"{where}: {name}: a rational with a zero denominator; expected finite values")
        return _Entry(typ, count, np.divide(num, den, out=np.zeros_like(num), where=den != 0))
    dt = {"B": "u1", "b": "i1", "H": "u2", "h": "i2", "I": "u4", "i": "i4", "f": "f4", "d": "f8"}[fmt]
    return _Entry(typ, count, np.frombuffer(raw, dtype=np.dtype(order + dt)).astype(np.float64))


def parse_dcp(data: bytes, where: str = "profile.dcp") -> CameraProfile:
    """Parse the bytes of a ``.dcp`` file (see the module docstring); ``where`` names it in errors."""
    if len(data) < 8:
        raise DngError(f"{where}: header: {len(data)} bytes; expected at least 8 (a DNG camera profile, 'IIRC')")
    magic = bytes(data[:4])
    if magic not in DCP_MAGIC:
        what = " (a TIFF/DNG file, not a camera profile)" if magic in (b"II*\0", b"MM\0*") else ""
        raise DngError(f"{where}: header: magic {magic!r}{what}; expected b'IIRC' or b'MMCR' (a DNG camera profile)")
    order = DCP_MAGIC[magic]
    (ifd,) = struct.unpack(order + "I", data[4:8])
    if ifd < 8 or ifd + 2 > len(data):
        raise DngError(f"{where}: header: IFD offset {ifd} outside the file ({len(data)} bytes); "
                       f"expected an offset in [8, {len(data) - 2}]")
    (n,) = struct.unpack(order + "H", data[ifd:ifd + 2])
    if n == 0 or ifd + 2 + 12 * n > len(data):
        raise DngError(f"{where}: IFD: {n} entries at byte {ifd} do not fit in the file ({len(data)} bytes); "
                       f"expected 1 or more complete 12-byte entries (truncated file?)")
    entries: dict[int, _Entry] = {}
    for k in range(n):
        off = ifd + 2 + 12 * k
        code, typ, count = struct.unpack(order + "HHI", data[off:off + 8])
        name = _NAMES.get(code, f"tag {code}")
        if code in entries:
            raise DngError(f"{where}: {name}: appears twice in the IFD; expected each tag once")
        if typ not in _TYPES:
            if code in _NAMES:
                raise DngError(f"{where}: {name}: unknown TIFF field type {typ}; expected one of 1-12")
            continue  # an unknown tag of an unknown type: skipped, as TIFF readers do
        if count == 0:
            raise DngError(f"{where}: {name}: count 0; expected at least one value")
        if code in _NAMES:
            entries[code] = _decode(where, data, order, code, typ, count, data[off + 8:off + 12])
    return _profile(_TagSource(where, entries), require_color_matrix=True)


def read_dcp(path: str | os.PathLike) -> CameraProfile:
    """Read and validate a DNG camera profile file (``.dcp``).

    Raises
    ------
    DngError
        Missing file, not a DCP, truncated, or a malformed tag (one line naming file and tag).
    """
    p = Path(path)
    if not p.exists():
        raise DngError(f"{p}: no such file; expected a DNG camera profile (.dcp)")
    if p.is_dir():
        raise DngError(f"{p}: is a directory; expected a DNG camera profile (.dcp)")
    size = p.stat().st_size
    if size > MAX_DCP_BYTES:
        raise DngError(f"{p}: {size} bytes; expected a camera profile of at most {MAX_DCP_BYTES} bytes")
    return parse_dcp(p.read_bytes(), str(p))


# ---------------------------------------------------------------------------------------------
# profile tags embedded in a DNG (IFD 0 as tifffile parsed it)
# ---------------------------------------------------------------------------------------------

#: Tags whose presence in a DNG makes an embedded profile worth recording (the colour matrices
#: and illuminants are in CameraMeta already).
_RENDER_TAGS = ("ProfileHueSatMapDims", "ProfileHueSatMapData1", "ProfileLookTableDims", "ProfileLookTableData",
                "ProfileToneCurve", "BaselineExposureOffset", "DefaultBlackRender", "ProfileHueSatMapEncoding",
                "ProfileLookTableEncoding", "ProfileCalibrationSignature", "CameraCalibrationSignature")


def _tifffile_entry(tag) -> _Entry:
    typ, value = int(tag.dtype), tag.value
    if typ == 2 or isinstance(value, str):
        return _Entry(2, int(tag.count), str(value))
    if isinstance(value, (bytes, bytearray)):
        return _Entry(typ, int(tag.count), np.frombuffer(bytes(value), np.uint8).astype(np.float64))
    vals = np.atleast_1d(np.asarray(value, dtype=np.float64)).ravel()
    if typ in (5, 10):  # tifffile keeps rationals as (numerator, denominator) pairs
        if vals.size % 2:
            raise DngError(f"odd number of rational parts ({vals.size})")
        num, den = vals[0::2], vals[1::2]
        vals = np.divide(num, den, out=np.zeros_like(num), where=den != 0)
    return _Entry(typ, int(tag.count), vals)


def embedded_profile_extra(ifd0, path: str | os.PathLike, get: Callable | None = None) -> dict[str, Any]:
    """``{"camera_profile": CameraProfile}`` from the profile tags of a DNG's IFD 0 (tifffile page), or ``{}``.

    Empty when the DNG has none of the rendering tags (HueSatMap, LookTable, ToneCurve,
    BaselineExposureOffset, DefaultBlackRender, encodings, calibration signatures): its
    colour matrices are in :class:`~simcam.frame.CameraMeta` already.
    """
    tags = ifd0.tags
    entries: dict[int, _Entry] = {}
    for code, name in _NAMES.items():
        t = tags.get(code)
        if t is None:
            continue
        try:
            entries[code] = _tifffile_entry(t)
        except (TypeError, ValueError, DngError) as exc:
            raise DngError(f"{path}: {name}: malformed value ({exc}); expected {name}'s numbers") from None
    src = _TagSource(str(path), entries)
    if not any(src.has(n) for n in _RENDER_TAGS):
        return {}
    return {"camera_profile": _profile(src, require_color_matrix=False)}
