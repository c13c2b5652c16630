"""DNG opcode lists: parse and serialise (DNG 1.6 specification, chapter 7).

An opcode list (tags OpcodeList1/2/3, type UNDEFINED) is always big-endian,
whatever the byte order of the file::

    uint32 count
    count x { uint32 id; uint8 version[4]; uint32 flags; uint32 n; uint8 payload[n] }

Every opcode is kept as a :class:`simcam.frame.Opcode` with its payload bytes,
so a list round-trips byte-exactly. GainMap (id 9) payloads are also decoded
into :class:`simcam.frame.GainMap`; :func:`encode_gain_map` is the exact inverse
of :func:`decode_gain_map`.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from ..errors import DngError
from ..frame import GainMap, Opcode

GAIN_MAP_ID = 9
#: GainMap header: Top, Left, Bottom, Right, Plane, Planes, RowPitch, ColPitch,
#: MapPointsV, MapPointsH (uint32), MapSpacingV, MapSpacingH, MapOriginV,
#: MapOriginH (float64), MapPlanes (uint32). DNG 1.6 spec, "GainMap".
_GAIN_MAP_HEADER = struct.Struct(">10I4dI")
_OPCODE_HEADER = struct.Struct(">I4BII")
#: Largest gain simcam applies: a gain above it would lift any non-zero 16-bit code past white.
MAX_GAIN = 65536.0
#: Smallest normal float64; a subnormal MapSpacing would overflow the map position of a pixel.
_MIN_NORMAL = float(np.finfo(np.float64).tiny)


def decode_gain_map(payload: bytes, *, where: str = "GainMap") -> GainMap:
    """Decode a GainMap opcode payload (big-endian) and check its parameters.

    Parameters
    ----------
    payload : bytes
        The opcode's parameter bytes (76-byte header + float32 gains).
    where : str
        Prefix for error messages (file and tag).

    Returns
    -------
    GainMap
        ``gains`` has shape (MapPointsV, MapPointsH, MapPlanes), float32, read-only (the
        metadata is shared between frames, never copied per stage).

    Raises
    ------
    DngError
        A payload of the wrong size, or a parameter the DNG SDK refuses or simcam cannot apply
        (:func:`check_gain_map`).
    """
    if len(payload) < _GAIN_MAP_HEADER.size:
        raise DngError(f"{where}: GainMap payload of {len(payload)} bytes; expected at least {_GAIN_MAP_HEADER.size}")
    (top, left, bottom, right, plane, planes, row_pitch, col_pitch, points_v, points_h,
     spacing_v, spacing_h, origin_v, origin_h, map_planes) = _GAIN_MAP_HEADER.unpack_from(payload)
    n = points_v * points_h * map_planes
    want = _GAIN_MAP_HEADER.size + 4 * n
    if len(payload) != want:
        raise DngError(
            f"{where}: GainMap of {points_v}x{points_h}x{map_planes} points needs {want} bytes, payload has {len(payload)}")
    if points_v < 1 or points_h < 1 or map_planes < 1:
        raise DngError(f"{where}: GainMap MapPointsV/H/MapPlanes = {points_v}/{points_h}/{map_planes}; expected >= 1")
    gains = np.frombuffer(payload, dtype=">f4", count=n, offset=_GAIN_MAP_HEADER.size)
    gains = gains.astype(np.float32).reshape(points_v, points_h, map_planes)
    gains.setflags(write=False)
    gm = GainMap(top=top, left=left, bottom=bottom, right=right, plane=plane, planes=planes,
                 row_pitch=row_pitch, col_pitch=col_pitch, map_spacing_v=spacing_v, map_spacing_h=spacing_h,
                 map_origin_v=origin_v, map_origin_h=origin_h, gains=gains)
    check_gain_map(gm, where=where)
    return gm


def _check_axis(points: int, spacing: float, origin: float, axis: str, where: str) -> None:
    """MapSpacing / MapOrigin of one axis (ignored by the SDK for a one-point axis)."""
    if points == 1:
        return
    if not (math.isfinite(spacing) and spacing >= _MIN_NORMAL):
        raise DngError(f"{where}: GainMap MapSpacing{axis} {spacing!r}; expected a finite number > 0 "
                       f"(at least {_MIN_NORMAL:.3g})")
    if not math.isfinite(origin):
        raise DngError(f"{where}: GainMap MapOrigin{axis} {origin!r}; expected a finite number")


def check_gain_map(gm: GainMap, *, where: str = "GainMap") -> None:
    """Check a GainMap's parameters (DNG 1.7.0.0 section 7, opcode 9; DNG SDK ``dng_gain_map::GetStream``).

    As the SDK: MapSpacing > 0 on an axis of more than one point (a one-point axis ignores spacing
    and origin), at least one point and plane; as ``dng_area_spec``: Planes, RowPitch and ColPitch
    at least 1. Beyond the SDK, so that no NaN or infinity reaches the image: spacing and origin
    finite (spacing a normal float64), gains finite and within 0 .. :data:`MAX_GAIN`.
    """
    if gm.planes < 1 or gm.row_pitch < 1 or gm.col_pitch < 1:
        raise DngError(f"{where}: GainMap Planes/RowPitch/ColPitch = {gm.planes}/{gm.row_pitch}/{gm.col_pitch}; "
                       f"expected >= 1")
    pv, ph = int(gm.gains.shape[0]), int(gm.gains.shape[1])
    _check_axis(pv, float(gm.map_spacing_v), float(gm.map_origin_v), "V", where)
    _check_axis(ph, float(gm.map_spacing_h), float(gm.map_origin_h), "H", where)
    g = np.asarray(gm.gains)
    if not (g.min() >= 0 and g.max() <= MAX_GAIN):  # NaN fails both comparisons
        bad = ~(np.isfinite(g) & (g >= 0) & (g <= MAX_GAIN))
        raise DngError(f"{where}: GainMap gain {float(g[bad][0])!r}; expected finite gains 0 to {MAX_GAIN:g}")


def encode_gain_map(gm: GainMap) -> bytes:
    """Serialise a :class:`GainMap` to its opcode payload (inverse of :func:`decode_gain_map`)."""
    gains = np.asarray(gm.gains, dtype=np.float32)
    if gains.ndim == 2:
        gains = gains[:, :, None]
    if gains.ndim != 3:
        raise DngError(f"GainMap.gains: expected shape (points_v, points_h, planes), got {gains.shape}")
    pv, ph, mp = gains.shape
    head = _GAIN_MAP_HEADER.pack(int(gm.top), int(gm.left), int(gm.bottom), int(gm.right), int(gm.plane),
                                 int(gm.planes), int(gm.row_pitch), int(gm.col_pitch), pv, ph,
                                 float(gm.map_spacing_v), float(gm.map_spacing_h), float(gm.map_origin_v),
                                 float(gm.map_origin_h), mp)
    return head + gains.astype(">f4").tobytes()


def gain_map_opcode(gm: GainMap, *, version: tuple[int, int, int, int] = (1, 3, 0, 0), flags: int = 0) -> Opcode:
    """An :class:`Opcode` (id 9) carrying ``gm`` (payload encoded, ``parsed`` set)."""
    return Opcode(id=GAIN_MAP_ID, version=tuple(version), flags=int(flags), payload=encode_gain_map(gm), parsed=gm)


def parse_opcode_list(data: bytes, *, where: str = "OpcodeList") -> list[Opcode]:
    """Parse an opcode-list tag value into :class:`Opcode` objects.

    Parameters
    ----------
    data : bytes
        The tag's bytes (big-endian, DNG 1.6 spec section 7.1).
    where : str
        Prefix for error messages, e.g. ``"x.dng: OpcodeList2"``.

    Returns
    -------
    list of Opcode
        In file order; GainMaps have ``parsed`` set to a :class:`GainMap`.
    """
    data = bytes(data)
    if len(data) < 4:
        raise DngError(f"{where}: {len(data)} bytes; expected at least 4 (the opcode count)")
    (count,) = struct.unpack_from(">I", data, 0)
    pos = 4
    ops: list[Opcode] = []
    for k in range(count):
        if pos + _OPCODE_HEADER.size > len(data):
            raise DngError(f"{where}: opcode {k} of {count} starts past the end of the {len(data)}-byte list")
        oid, v0, v1, v2, v3, flags, n = _OPCODE_HEADER.unpack_from(data, pos)
        pos += _OPCODE_HEADER.size
        if pos + n > len(data):
            raise DngError(f"{where}: opcode {k} (id {oid}) declares {n} parameter bytes, only {len(data) - pos} left")
        payload = data[pos:pos + n]
        pos += n
        op = Opcode(id=oid, version=(v0, v1, v2, v3), flags=flags, payload=payload)
        if oid == GAIN_MAP_ID:
            op.parsed = decode_gain_map(payload, where=f"{where}[{k}]")
        ops.append(op)
    if pos != len(data):
        raise DngError(f"{where}: {len(data) - pos} trailing bytes after {count} opcodes; expected none")
    return ops


def serialise_opcode_list(ops: list[Opcode]) -> bytes:
    """Bytes of an opcode-list tag (inverse of :func:`parse_opcode_list`; payload bytes are authoritative)."""
    out = [struct.pack(">I", len(ops))]
    for op in ops:
        payload = bytes(op.payload)
        out.append(_OPCODE_HEADER.pack(int(op.id), *(int(v) for v in op.version), int(op.flags), len(payload)))
        out.append(payload)
    return b"".join(out)


#: Work cap of one opcode list, in samples touched: at most ``max(MAX_OPCODE_WORK,
#: OPCODE_WORK_FACTOR x the samples of the image it applies to)`` (real files touch each sample
#: about once: four GainMaps of pitch 2, one per Bayer phase).
MAX_OPCODE_WORK = 1 << 28
OPCODE_WORK_FACTOR = 8
#: Opcodes that cost no pass over the image (TrimBounds) or that simcam does not apply.
_FREE_OPCODES = {6}
_APPLIED_OPCODES = {1, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13}


def _grid_count(start: int, stop: int, pitch: int, size: int) -> int:
    """How many of ``start, start + pitch, ... < stop`` lie in ``0 .. size - 1`` (start >= 0)."""
    stop = min(int(stop), size)
    return max(0, -(-(stop - int(start)) // max(int(pitch), 1)))


def gain_map_samples(gm: GainMap, height: int, width: int, planes: int) -> int:
    """Samples a GainMap multiplies on a ``height x width x planes`` image (its area spec, DNG 1.7.0.0 sec. 7)."""
    rows = _grid_count(gm.top, gm.bottom, gm.row_pitch, height)
    cols = _grid_count(gm.left, gm.right, gm.col_pitch, width)
    n_planes = max(0, min(int(gm.plane) + max(int(gm.planes), 1), planes) - int(gm.plane))
    return rows * cols * n_planes


def opcode_list_work(ops: list[Opcode], height: int, width: int, planes: int) -> int:
    """Samples an opcode list touches: each GainMap its selection, any other applied opcode the whole image."""
    work = 0
    for op in ops:
        if isinstance(op.parsed, GainMap):
            work += gain_map_samples(op.parsed, height, width, planes)
        elif op.id in _APPLIED_OPCODES and op.id not in _FREE_OPCODES:
            work += height * width * planes
    return work


def check_opcode_work(ops: list[Opcode], height: int, width: int, planes: int, *, where: str) -> None:
    """Refuse an opcode list that would take far more passes over the image than any camera writes.

    The cost of a list is linear in the samples its opcodes touch (:func:`opcode_list_work`), so a
    small file with tens of thousands of whole-image GainMaps would take minutes on a large image.
    """
    samples = height * width * planes
    cap = max(MAX_OPCODE_WORK, OPCODE_WORK_FACTOR * samples)
    work = opcode_list_work(ops, height, width, planes)
    if work > cap:
        raise DngError(f"{where}: {len(ops)} opcodes touch {work} samples of the {width}x{height}x{planes} image; "
                       f"expected at most {cap} ({OPCODE_WORK_FACTOR} passes over the image, or 2^28 samples)")
