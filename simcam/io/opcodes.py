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


def decode_gain_map(payload: bytes, *, where: str = "GainMap") -> GainMap:
    """Decode a GainMap opcode payload (big-endian).

    Parameters
    ----------
    payload : bytes
        The opcode's parameter bytes (76-byte header + float32 gains).
    where : str
        Prefix for error messages (file and tag).

    Returns
    -------
    GainMap
        ``gains`` has shape (MapPointsV, MapPointsH, MapPlanes), float32.
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
    return GainMap(top=top, left=left, bottom=bottom, right=right, plane=plane, planes=planes,
                   row_pitch=row_pitch, col_pitch=col_pitch, map_spacing_v=spacing_v, map_spacing_h=spacing_h,
                   map_origin_v=origin_v, map_origin_h=origin_h, gains=gains)


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
