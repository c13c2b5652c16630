"""Write uncompressed CFA DNG files (uint16 samples) with simcam metadata.

The file is a little-endian classic TIFF with one IFD (IFD0 = the raw image,
NewSubfileType 0, PhotometricInterpretation 32803, one strip). Tags follow the
DNG 1.6 specification, chapter 4. Everything :func:`simcam.io.dng.read_dng`
reads is written when the metadata holds it, so ``read_dng(write_dng(...))``
returns the same :class:`CameraMeta`, with these documented exceptions:

* ``origin`` — the written data becomes the stored image, so it reads back as
  (0, 0) (the active area is translated by ``-origin``);
* ``unique_camera_model`` — the tag is required; an empty value is written as
  ``"<make> <model>"`` or ``"simcam synthetic"``;
* rationals — floats are stored as the simplest 32-bit fraction that divides
  back to the same float64 when one exists (every value read from a DNG, and
  decimals up to 9 digits); other floats come back within ~1e-9 relative;
* ``white_level`` and ``linearization_table`` are integer tags (rounded);
  ``iso`` is a SHORT (rounded); ``iso``/``exposure_time_s`` <= 0 read back None;
* ``white_balance_gains``, ``camera_id``, ``source`` and ``extra`` have no tag.
"""

from __future__ import annotations

import math
import os
import struct
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ..cfa import shift_pattern
from .atomic import atomic_output
from ..errors import DngError
from ..frame import CameraMeta, RawFrame
from .dng import T
from .opcodes import serialise_opcode_list

# TIFF field types
BYTE, ASCII, SHORT, LONG, RATIONAL, UNDEFINED, SRATIONAL, DOUBLE = 1, 2, 3, 4, 5, 7, 10, 12
_TYPE_SIZE = {BYTE: 1, ASCII: 1, SHORT: 2, LONG: 4, RATIONAL: 8, UNDEFINED: 1, SRATIONAL: 8, DOUBLE: 8}
_CFA_CODES = {"R": 0, "G": 1, "B": 2}


def to_rational(x: float, *, signed: bool, where: str = "value") -> tuple[int, int]:
    """Encode ``x`` as a (num, den) pair of 32-bit integers.

    Picks the fraction with the smallest denominator (searched over 10^k
    limits) whose float64 quotient equals ``x`` exactly; falls back to the
    closest fraction with a denominator below 2^31.
    """
    x = float(x)
    if not math.isfinite(x):
        raise DngError(f"{where}: {x} cannot be stored as a rational")
    lo, hi = (-(2 ** 31), 2 ** 31 - 1) if signed else (0, 2 ** 32 - 1)
    if x < 0 and not signed:
        raise DngError(f"{where}: {x} is negative; the tag is an unsigned RATIONAL")
    frac = Fraction(x)
    best = None
    for k in range(0, 10):
        f = frac.limit_denominator(10 ** k)
        if lo <= f.numerator <= hi and f.numerator / f.denominator == x:
            return f.numerator, f.denominator
    for lim in (2 ** 31 - 1, 2 ** 24, 2 ** 20, 10 ** 6, 10 ** 4, 1):
        f = frac.limit_denominator(lim)
        if lo <= f.numerator <= hi:
            best = f
            break
    if best is None:
        raise DngError(f"{where}: {x} is out of the 32-bit rational range")
    return best.numerator, best.denominator


class _IFDBuilder:
    """Collects (tag, type, values) entries and packs a little-endian IFD."""

    def __init__(self) -> None:
        self.entries: dict[int, tuple[int, int, bytes]] = {}

    def add(self, code: int, typ: int, values: Any, *, where: str = "") -> None:
        where = where or str(code)
        if typ == ASCII:
            raw = str(values).encode("latin-1", "replace") + b"\0"
            count = len(raw)
        elif typ in (BYTE, UNDEFINED):
            raw = bytes(values) if isinstance(values, (bytes, bytearray)) else bytes(int(v) for v in values)
            count = len(raw)
        else:
            vals = np.atleast_1d(np.asarray(values, dtype=np.float64)).ravel()
            count = vals.size
            if typ == SHORT:
                iv = np.round(vals).astype(np.int64)
                if np.any(iv < 0) or np.any(iv > 65535):
                    raise DngError(f"{where}: values {iv.min()}..{iv.max()} do not fit a SHORT tag (0..65535)")
                raw = iv.astype("<u2").tobytes()
            elif typ == LONG:
                iv = np.round(vals).astype(np.int64)
                if np.any(iv < 0) or np.any(iv > 2 ** 32 - 1):
                    raise DngError(f"{where}: values do not fit a LONG tag (0..2^32-1)")
                raw = iv.astype("<u4").tobytes()
            elif typ in (RATIONAL, SRATIONAL):
                parts = [to_rational(v, signed=typ == SRATIONAL, where=where) for v in vals]
                raw = np.asarray(parts, dtype="<i4" if typ == SRATIONAL else "<u4").tobytes()
            elif typ == DOUBLE:
                raw = vals.astype("<f8").tobytes()
            else:  # pragma: no cover - internal misuse
                raise ValueError(typ)
        self.entries[int(code)] = (typ, count, raw)

    def pack(self, ifd_offset: int) -> tuple[bytes, dict[int, int]]:
        """IFD bytes placed at ``ifd_offset`` (out-of-line values appended after it)."""
        codes = sorted(self.entries)
        n = len(codes)
        data_start = ifd_offset + 2 + 12 * n + 4
        head = [struct.pack("<H", n)]
        blob = bytearray()
        value_offsets = {}
        for code in codes:
            typ, count, raw = self.entries[code]
            if len(raw) <= 4:
                field = raw.ljust(4, b"\0")
            else:
                if (data_start + len(blob)) % 2:
                    blob += b"\0"
                value_offsets[code] = data_start + len(blob)
                field = struct.pack("<I", data_start + len(blob))
                blob += raw
            head.append(struct.pack("<HHI", code, typ, count) + field)
        head.append(struct.pack("<I", 0))
        return b"".join(head) + bytes(blob), value_offsets


def _dn_samples(frame: RawFrame, *, clip: bool, where: str) -> np.ndarray:
    from ..raw import black_level_map

    meta = frame.meta
    # float32 is exact for integers below 2^24, so DN data needs no float64 copy
    data = np.asarray(frame.data, dtype=np.float64 if frame.kind == "raw" else np.float32)
    if frame.kind == "raw":
        if meta.linearization_table is not None:
            raise DngError(f"{where}: cannot de-normalise a 'raw' frame through a LinearizationTable; "
                           f"pass kind 'raw_dn' data")
        black = black_level_map(meta, data.shape).astype(np.float64)
        data = data * (float(meta.white_level) - black) + black
    elif frame.kind != "raw_dn":
        raise DngError(f"{where}: frame kind {frame.kind!r}; expected 'raw_dn' or 'raw' (a CFA mosaic)")
    if not np.all(np.isfinite(data)):
        raise DngError(f"{where}: pixel data contains NaN or infinite values")
    dn = np.rint(data)
    lo, hi = float(dn.min()), float(dn.max())
    if lo < 0 or hi > 65535:
        if not clip:
            raise DngError(f"{where}: pixel values {lo}..{hi} DN outside the uint16 range 0..65535 (clip=False)")
        np.clip(dn, 0, 65535, out=dn)
    return dn.astype("<u2")


def _file_geometry(meta: CameraMeta, h: int, w: int, where: str):
    """Active area of the written file (translated by -origin) and the file's CFAPattern."""
    oy, ox = meta.origin
    if meta.active_area is None:
        active = None
        top = left = 0
    else:
        t, l, b, r = (int(v) for v in meta.active_area)
        t, l, b, r = t - oy, l - ox, min(b - oy, h), min(r - ox, w)
        if t < 0 or l < 0:
            raise DngError(
                f"{where}: meta.origin {tuple(meta.origin)} lies inside the active area {list(meta.active_area)}; "
                f"the opcode and black-level anchors would move: crop to the active area first, or set "
                f"active_area=None and origin=(0, 0)")
        if not (t < b and l < r):
            raise DngError(f"{where}: active area {list(meta.active_area)} does not overlap the {h}x{w} data "
                           f"at origin {tuple(meta.origin)}")
        active = (t, l, b, r)
        top, left = t, l
    # meta.cfa describes data[0, 0]; the DNG CFAPattern is anchored at the active area's top-left.
    cfa_tag = shift_pattern(meta.cfa, top, left)
    return active, cfa_tag


def write_dng(path: str | os.PathLike, frame: RawFrame | np.ndarray, meta: CameraMeta | None = None, *,
              dng_version: tuple[int, int, int, int] = (1, 4, 0, 0), clip: bool = True,
              protect: tuple[str | os.PathLike, ...] = (), software: str = "simcam") -> Path:
    """Write an uncompressed 16-bit CFA DNG.

    Parameters
    ----------
    path : path-like
        Output file (``.dng``). Written to a temporary file beside it, then
        renamed; never overwrites ``meta.source`` or any path in ``protect``.
    frame : RawFrame or ndarray
        A mosaic frame of kind ``raw_dn`` (DN) or ``raw`` (normalised; turned
        back into DN with the metadata's black/white levels), or an H x W
        array of DN with ``meta``.
    meta : CameraMeta, optional
        Required with an array; with a RawFrame it replaces ``frame.meta``.
    dng_version : 4-tuple
        DNGVersion tag, (1, 4, 0, 0) or (1, 6, 0, 0).
    clip : bool
        Clip DN to 0..65535 (True) or raise if any value is outside (False).
        Values are rounded to the nearest integer.
    protect : paths
        Files that must never be overwritten (inputs).
    software : str
        Software tag.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    if isinstance(frame, RawFrame):
        if meta is not None:
            frame = frame.evolve(meta=meta)
    else:
        if meta is None:
            raise DngError(f"{path}: write_dng(path, data, meta): meta is required with an array")
        frame = RawFrame(np.asarray(frame, dtype=np.float32) if np.asarray(frame).dtype != np.float32
                         else frame, meta, kind="raw_dn")
        if np.asarray(frame.data).size and np.any(np.abs(frame.data) >= 2 ** 24):
            raise DngError(f"{path}: data exceeds the float32-exact integer range")
    meta = frame.meta
    where = str(path)
    if frame.kind not in ("raw_dn", "raw"):
        raise DngError(f"{where}: frame kind {frame.kind!r}; expected 'raw_dn' or 'raw' (a CFA mosaic)")
    if frame.data.ndim != 2:
        raise DngError(f"{where}: data shape {frame.data.shape}; expected an H x W CFA mosaic")
    if meta.cfa is None:
        raise DngError(f"{where}: meta.cfa is None; expected a Bayer pattern (RGGB, BGGR, GRBG, GBRG)")
    if tuple(dng_version[:2]) not in ((1, 4), (1, 5), (1, 6), (1, 3)):
        raise DngError(f"{where}: dng_version {dng_version}; expected (1, 4, 0, 0) or (1, 6, 0, 0)")
    for p in tuple(protect) + ((meta.source,) if meta.source else ()):
        if p and Path(p).exists() and path.exists() and os.path.samefile(p, path):
            raise DngError(f"{where}: refusing to overwrite the input file {p}")
    if path.is_dir():
        raise DngError(f"{where}: is a directory; expected a file name")
    if not path.parent.exists():
        raise DngError(f"{where}: output folder {path.parent} does not exist")

    h, w = frame.data.shape
    samples = _dn_samples(frame, clip=clip, where=where)
    active, cfa_tag = _file_geometry(meta, h, w, where)

    ifd = _IFDBuilder()
    add = ifd.add
    add(T["NewSubfileType"], LONG, 0)
    add(T["ImageWidth"], LONG, w)
    add(T["ImageLength"], LONG, h)
    add(T["BitsPerSample"], SHORT, 16)
    add(T["Compression"], SHORT, 1)
    add(T["PhotometricInterpretation"], SHORT, 32803)
    if meta.make:
        add(T["Make"], ASCII, meta.make)
    if meta.model:
        add(T["Model"], ASCII, meta.model)
    add(T["StripOffsets"], LONG, 0)  # patched below
    add(T["Orientation"], SHORT, int(meta.orientation), where=f"{where}: Orientation")
    add(T["SamplesPerPixel"], SHORT, 1)
    add(T["RowsPerStrip"], LONG, h)
    add(T["StripByteCounts"], LONG, samples.nbytes)
    add(T["PlanarConfiguration"], SHORT, 1)
    add(305, ASCII, software)
    add(T["CFARepeatPatternDim"], SHORT, [2, 2])
    add(T["CFAPattern"], BYTE, [_CFA_CODES[c] for c in cfa_tag])
    if meta.exposure_time_s is not None and meta.exposure_time_s > 0:
        add(T["ExposureTime"], RATIONAL, meta.exposure_time_s, where=f"{where}: ExposureTime")
    if meta.iso is not None and meta.iso > 0:
        add(T["ISOSpeedRatings"], SHORT, meta.iso, where=f"{where}: ISOSpeedRatings")
    add(T["DNGVersion"], BYTE, list(dng_version))
    has_ops = bool(meta.opcode_list1 or meta.opcode_list2 or meta.opcode_list3)
    add(T["DNGBackwardVersion"], BYTE, [1, 3, 0, 0] if has_ops else [1, 1, 0, 0])
    ucm = meta.unique_camera_model or f"{meta.make} {meta.model}".strip() or "simcam synthetic"
    add(T["UniqueCameraModel"], ASCII, ucm)
    add(T["CFAPlaneColor"], BYTE, [0, 1, 2])
    add(T["CFALayout"], SHORT, 1)
    if meta.linearization_table is not None:
        add(T["LinearizationTable"], SHORT, meta.linearization_table, where=f"{where}: LinearizationTable")
    bl = np.asarray(meta.black_level, dtype=np.float64)
    if bl.ndim == 0:
        bl = bl.reshape(1, 1)
    if bl.ndim == 3:
        bl = bl[..., 0]
    if bl.ndim != 2:
        raise DngError(f"{where}: meta.black_level shape {bl.shape}; expected (rows, cols)")
    add(T["BlackLevelRepeatDim"], SHORT, list(bl.shape))
    add(T["BlackLevel"], RATIONAL, bl.ravel(), where=f"{where}: BlackLevel")
    if meta.black_level_delta_h is not None:
        add(T["BlackLevelDeltaH"], SRATIONAL, meta.black_level_delta_h, where=f"{where}: BlackLevelDeltaH")
    if meta.black_level_delta_v is not None:
        add(T["BlackLevelDeltaV"], SRATIONAL, meta.black_level_delta_v, where=f"{where}: BlackLevelDeltaV")
    add(T["WhiteLevel"], LONG, meta.white_level, where=f"{where}: WhiteLevel")
    if meta.default_crop_origin is not None:
        add(T["DefaultCropOrigin"], RATIONAL, meta.default_crop_origin, where=f"{where}: DefaultCropOrigin")
    if meta.default_crop_size is not None:
        add(T["DefaultCropSize"], RATIONAL, meta.default_crop_size, where=f"{where}: DefaultCropSize")
    for name, attr, typ, n in (
        ("ColorMatrix1", "color_matrix1", SRATIONAL, 9), ("ColorMatrix2", "color_matrix2", SRATIONAL, 9),
        ("CameraCalibration1", "camera_calibration1", SRATIONAL, 9),
        ("CameraCalibration2", "camera_calibration2", SRATIONAL, 9),
        ("AnalogBalance", "analog_balance", RATIONAL, 3), ("AsShotNeutral", "as_shot_neutral", RATIONAL, 3),
        ("AsShotWhiteXY", "as_shot_white_xy", RATIONAL, 2),
        ("ForwardMatrix1", "forward_matrix1", SRATIONAL, 9), ("ForwardMatrix2", "forward_matrix2", SRATIONAL, 9),
    ):
        v = getattr(meta, attr)
        if v is None:
            continue
        v = np.asarray(v, dtype=np.float64).ravel()
        if v.size != n:
            raise DngError(f"{where}: meta.{attr} has {v.size} values; expected {n} ({name})")
        add(T[name], typ, v, where=f"{where}: {name}")
    add(T["BaselineExposure"], SRATIONAL, meta.baseline_exposure, where=f"{where}: BaselineExposure")
    if meta.calibration_illuminant1 is not None:
        add(T["CalibrationIlluminant1"], SHORT, meta.calibration_illuminant1)
    if meta.calibration_illuminant2 is not None:
        add(T["CalibrationIlluminant2"], SHORT, meta.calibration_illuminant2)
    if active is not None:
        add(T["ActiveArea"], LONG, list(active))
    for k in (1, 2, 3):
        ops = getattr(meta, f"opcode_list{k}")
        if ops:
            add(T[f"OpcodeList{k}"], UNDEFINED, serialise_opcode_list(ops))
    if meta.noise_profile is not None:
        npf = np.asarray(meta.noise_profile, dtype=np.float64).ravel()
        if npf.size == 0 or npf.size % 2:
            raise DngError(f"{where}: meta.noise_profile has {npf.size} values; expected (S, O) pairs")
        add(T["NoiseProfile"], DOUBLE, npf)

    # Layout: header | IFD + values | pixel strip (16-byte aligned).
    ifd_bytes, _ = ifd.pack(8)
    strip_offset = (8 + len(ifd_bytes) + 15) // 16 * 16
    add(T["StripOffsets"], LONG, strip_offset)
    ifd_bytes, _ = ifd.pack(8)
    assert 8 + len(ifd_bytes) <= strip_offset
    header = b"II" + struct.pack("<HI", 42, 8)
    body = header + ifd_bytes
    body += b"\0" * (strip_offset - len(body))

    with atomic_output(path, suffix=".dng.tmp") as tmp:
        with open(tmp, "wb") as f:
            f.write(body)
            f.write(np.ascontiguousarray(samples).tobytes())
    return path
