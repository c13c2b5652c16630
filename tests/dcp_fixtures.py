"""Helpers for camera-profile tests: build ``.dcp`` bytes and add profile tags to a DNG.

``dcp_bytes(tags)`` writes a DNG camera profile (one IFD, "IIRC" or "MMCR") from a list of
``(code, type, values)``; ``add_ifd0_tags(path, tags)`` appends a new IFD 0 to a classic
little-endian TIFF/DNG holding its old entries plus ``tags`` (values after the old data, so
every old offset stays valid) and points the header at it.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from simcam.io.dcp import PROFILE_TAGS as TAG

BYTE, ASCII, SHORT, LONG, RATIONAL, SLONG, SRATIONAL, FLOAT, DOUBLE = 1, 2, 3, 4, 5, 9, 10, 11, 12
_FMT = {BYTE: "B", SHORT: "H", LONG: "I", SLONG: "i", FLOAT: "f", DOUBLE: "d"}


def encode_values(typ: int, values, order: str = "<") -> tuple[int, bytes]:
    """(count, bytes) of a tag value."""
    if typ == ASCII:
        raw = str(values).encode("latin-1") + b"\0"
        return len(raw), raw
    vals = np.atleast_1d(np.asarray(values, dtype=np.float64)).ravel()
    if typ in (RATIONAL, SRATIONAL):
        den = 10000
        parts = []
        for v in vals:
            parts += [int(round(v * den)), den]
        return vals.size, struct.pack(order + ("i" if typ == SRATIONAL else "I") * len(parts), *parts)
    fmt = _FMT[typ]
    cast = float if fmt in "fd" else int
    return vals.size, struct.pack(order + fmt * vals.size, *[cast(v) for v in vals])


def _entries_blob(tags, start: int, order: str) -> tuple[list[bytes], bytes]:
    """12-byte entries (sorted by code) and the out-of-line values placed from byte ``start``."""
    entries, blob = [], bytearray()
    for code, typ, values in sorted(tags, key=lambda t: t[0]):
        if isinstance(values, (bytes, bytearray)):  # raw value bytes, count given as len/size
            count, raw = len(values) // {SHORT: 2, LONG: 4, FLOAT: 4, DOUBLE: 8}.get(typ, 1), bytes(values)
        else:
            count, raw = encode_values(typ, values, order)
        if len(raw) <= 4:
            field = raw.ljust(4, b"\0")
        else:
            if (start + len(blob)) % 2:
                blob += b"\0"
            field = struct.pack(order + "I", start + len(blob))
            blob += raw
        entries.append(struct.pack(order + "HHI", code, typ, count) + field)
    return entries, bytes(blob)


def dcp_bytes(tags, *, big_endian: bool = False) -> bytes:
    """A ``.dcp`` file: header, IFD at byte 8 with ``tags`` [(code, type, values)], then the values."""
    order = ">" if big_endian else "<"
    n = len(tags)
    start = 8 + 2 + 12 * n + 4
    entries, blob = _entries_blob(tags, start, order)
    head = (b"MMCR" if big_endian else b"IIRC") + struct.pack(order + "I", 8)
    return head + struct.pack(order + "H", n) + b"".join(entries) + struct.pack(order + "I", 0) + blob


def add_ifd0_tags(path: Path, tags) -> None:
    """Add (or replace) IFD 0 entries of a little-endian classic TIFF/DNG, in place."""
    data = bytearray(Path(path).read_bytes())
    assert data[:4] == b"II*\0", "little-endian classic TIFF expected"
    (ifd,) = struct.unpack("<I", data[4:8])
    (n,) = struct.unpack("<H", data[ifd:ifd + 2])
    old = {struct.unpack("<H", data[ifd + 2 + 12 * k:ifd + 4 + 12 * k])[0]: bytes(data[ifd + 2 + 12 * k:ifd + 14 + 12 * k])
           for k in range(n)}
    (next_ifd,) = struct.unpack("<I", data[ifd + 2 + 12 * n:ifd + 6 + 12 * n])
    new_codes = {c for c, _, _ in tags}
    kept = {c: e for c, e in old.items() if c not in new_codes}
    if len(data) % 2:
        data += b"\0"
    values_start = len(data)
    new_entries, blob = _entries_blob(tags, values_start, "<")
    data += blob
    if len(data) % 2:
        data += b"\0"
    all_entries = sorted(list(kept.items()) + [(struct.unpack("<H", e[:2])[0], e) for e in new_entries])
    new_ifd = len(data)
    data += struct.pack("<H", len(all_entries)) + b"".join(e for _, e in all_entries) + struct.pack("<I", next_ifd)
    data[4:8] = struct.pack("<I", new_ifd)
    Path(path).write_bytes(bytes(data))


def identity_table(h: int, s: int, v: int) -> np.ndarray:
    """(v, h, s, 3) float32 table of (0 degrees, x1, x1)."""
    t = np.zeros((v, h, s, 3), np.float32)
    t[..., 1:] = 1.0
    return t


#: A plausible camera: XYZ -> camera under illuminant A and D65, and forward matrices.
CM_A = [[0.8, -0.2, -0.05], [-0.5, 1.35, 0.15], [-0.1, 0.3, 0.55]]
CM_D65 = [[0.7, -0.15, -0.08], [-0.45, 1.3, 0.17], [-0.05, 0.2, 0.65]]
FM = [[0.65, 0.20, 0.11], [0.27, 0.70, 0.03], [0.03, 0.10, 0.70]]


def profile_tags(*, hsm1=None, hsm2=None, look=None, hsm_encoding=None, look_encoding=None, tone=None,
                 baseline_offset=None, black_render=None, forward=True, name="test profile"):
    """Tags of a dual-illuminant (A, D65) profile with optional tables."""
    tags = [(TAG["ColorMatrix1"], SRATIONAL, CM_A), (TAG["ColorMatrix2"], SRATIONAL, CM_D65),
            (TAG["CalibrationIlluminant1"], SHORT, 17), (TAG["CalibrationIlluminant2"], SHORT, 21),
            (TAG["ProfileName"], ASCII, name)]
    if forward:
        tags += [(TAG["ForwardMatrix1"], SRATIONAL, FM), (TAG["ForwardMatrix2"], SRATIONAL, FM)]
    for data, dims, names in ((hsm1, "ProfileHueSatMapDims", "ProfileHueSatMapData1"),
                              (look, "ProfileLookTableDims", "ProfileLookTableData")):
        if data is not None:
            v, h, s, _ = data.shape
            tags += [(TAG[dims], LONG, [h, s, v]), (TAG[names], FLOAT, data.ravel())]
    if hsm2 is not None:
        tags.append((TAG["ProfileHueSatMapData2"], FLOAT, hsm2.ravel()))
    if hsm_encoding is not None:
        tags.append((TAG["ProfileHueSatMapEncoding"], LONG, hsm_encoding))
    if look_encoding is not None:
        tags.append((TAG["ProfileLookTableEncoding"], LONG, look_encoding))
    if tone is not None:
        tags.append((TAG["ProfileToneCurve"], FLOAT, np.asarray(tone, np.float64).ravel()))
    if baseline_offset is not None:
        tags.append((TAG["BaselineExposureOffset"], SRATIONAL, baseline_offset))
    if black_render is not None:
        tags.append((TAG["DefaultBlackRender"], LONG, black_render))
    return tags


def write_dcp(path: Path, tags, **kw) -> Path:
    Path(path).write_bytes(dcp_bytes(tags, **kw))
    return Path(path)
