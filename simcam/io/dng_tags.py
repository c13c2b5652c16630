"""The TIFF / DNG tags simcam reads, and a check of their raw IFD entries before tifffile parses them.

tifffile turns a malformed entry into Python errors deep inside its page parser (an ImageLength with
two values is a tuple it compares with an int) or drops it with a log line. So the entries of IFD0 and
of its SubIFDs are read here first, 12 bytes at a time (TIFF 6.0 section 2, "Image File Directory"),
and every tag simcam uses is checked against the types and counts the specifications allow (Adobe
DNG Specification 1.7.0.0 chapter 4, each tag's "Type" and "Count"; TIFF 6.0 section 8 for the
baseline tags), and its data must lie inside the file. A failure is one :class:`DngError` line
naming the file and the tag.

Only classic TIFF is scanned (a DNG is one, DNG 1.7.0.0 chapter 3); anything else is left to
tifffile, whose errors the reader wraps.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path

from ..errors import DngError

# TIFF / DNG tag codes used by simcam (DNG 1.7.0.0 chapter 4; TIFF 6.0; TIFF/EP).
T = {
    "NewSubfileType": 254, "ImageWidth": 256, "ImageLength": 257, "BitsPerSample": 258,
    "Compression": 259, "PhotometricInterpretation": 262, "Make": 271, "Model": 272,
    "StripOffsets": 273, "Orientation": 274, "SamplesPerPixel": 277, "RowsPerStrip": 278,
    "StripByteCounts": 279, "PlanarConfiguration": 284, "TileWidth": 322, "TileLength": 323,
    "TileOffsets": 324, "TileByteCounts": 325, "SubIFDs": 330, "SampleFormat": 339,
    "CFARepeatPatternDim": 33421, "CFAPattern": 33422, "ExposureTime": 33434, "ExifTag": 34665,
    "ISOSpeedRatings": 34855,
    "DNGVersion": 50706, "DNGBackwardVersion": 50707, "UniqueCameraModel": 50708,
    "CFAPlaneColor": 50710, "CFALayout": 50711, "LinearizationTable": 50712,
    "BlackLevelRepeatDim": 50713, "BlackLevel": 50714, "BlackLevelDeltaH": 50715,
    "BlackLevelDeltaV": 50716, "WhiteLevel": 50717, "DefaultScale": 50718,
    "DefaultCropOrigin": 50719, "DefaultCropSize": 50720, "ColorMatrix1": 50721,
    "ColorMatrix2": 50722, "CameraCalibration1": 50723, "CameraCalibration2": 50724,
    "AnalogBalance": 50727, "AsShotNeutral": 50728, "AsShotWhiteXY": 50729,
    "BaselineExposure": 50730, "BaselineNoise": 50731, "CameraSerialNumber": 50735,
    "CalibrationIlluminant1": 50778, "CalibrationIlluminant2": 50779, "ActiveArea": 50829,
    "MaskedAreas": 50830, "ProfileName": 50936, "ForwardMatrix1": 50964, "ForwardMatrix2": 50965,
    "OpcodeList1": 51008, "OpcodeList2": 51009, "OpcodeList3": 51022, "NoiseProfile": 51041,
}
TAG_NAMES = {code: name for name, code in T.items()}

#: TIFF field types: code -> (name, bytes per value) (TIFF 6.0 section 2; 13 = IFD, TIFF Technical Note 1).
TIFF_TYPES = {1: ("BYTE", 1), 2: ("ASCII", 1), 3: ("SHORT", 2), 4: ("LONG", 4), 5: ("RATIONAL", 8),
              6: ("SBYTE", 1), 7: ("UNDEFINED", 1), 8: ("SSHORT", 2), 9: ("SLONG", 4), 10: ("SRATIONAL", 8),
              11: ("FLOAT", 4), 12: ("DOUBLE", 8), 13: ("IFD", 4)}
BYTE, ASCII, SHORT, LONG, RATIONAL, UNDEFINED, SRATIONAL, DOUBLE, IFD = 1, 2, 3, 4, 5, 7, 10, 12, 13
#: Most SubIFDs followed (real DNGs have one to three: raw, previews).
MAX_SUB_IFDS = 32


@dataclass(frozen=True)
class TagSpec:
    """Allowed TIFF types and value count (``count_min`` .. ``count_max``) of one tag."""

    types: tuple[int, ...]
    count_min: int = 1
    count_max: int | None = 1


_SL = (SHORT, LONG)
_TEXT = (ASCII, BYTE, UNDEFINED)
#: Tags of every image IFD tifffile parses (TIFF 6.0 section 8; strips and tiles section 15).
STRUCTURE_SPECS: dict[str, TagSpec] = {
    "NewSubfileType": TagSpec(_SL), "ImageWidth": TagSpec(_SL), "ImageLength": TagSpec(_SL),
    "BitsPerSample": TagSpec((SHORT,), 1, 16), "Compression": TagSpec((SHORT,)),
    "PhotometricInterpretation": TagSpec((SHORT,)), "SamplesPerPixel": TagSpec((SHORT,)),
    "RowsPerStrip": TagSpec(_SL), "PlanarConfiguration": TagSpec((SHORT,)),
    "StripOffsets": TagSpec(_SL, 1, None), "StripByteCounts": TagSpec(_SL, 1, None),
    "TileWidth": TagSpec(_SL), "TileLength": TagSpec(_SL),
    "TileOffsets": TagSpec((LONG,), 1, None), "TileByteCounts": TagSpec(_SL, 1, None),
    "SampleFormat": TagSpec((SHORT,), 1, 16), "SubIFDs": TagSpec((LONG, IFD), 1, MAX_SUB_IFDS),
}
#: DNG and TIFF/EP tags simcam reads from IFD0 or the raw IFD (DNG 1.7.0.0 chapter 4, "Type" / "Count").
DNG_SPECS: dict[str, TagSpec] = {
    "Make": TagSpec(_TEXT, 0, None), "Model": TagSpec(_TEXT, 0, None), "Orientation": TagSpec((SHORT,)),
    "CFARepeatPatternDim": TagSpec((SHORT,), 2, 2), "CFAPattern": TagSpec((BYTE,), 1, 64),
    "ExposureTime": TagSpec((RATIONAL,)), "ExifTag": TagSpec((LONG, IFD)),
    "ISOSpeedRatings": TagSpec(_SL, 1, 3),
    "DNGVersion": TagSpec((BYTE,), 4, 4), "DNGBackwardVersion": TagSpec((BYTE,), 4, 4),
    "UniqueCameraModel": TagSpec(_TEXT, 0, None), "CFAPlaneColor": TagSpec((BYTE,), 3, 4),
    "CFALayout": TagSpec((SHORT,)), "LinearizationTable": TagSpec((SHORT,), 1, 65536),
    "BlackLevelRepeatDim": TagSpec((SHORT,), 2, 2), "BlackLevel": TagSpec((SHORT, LONG, RATIONAL), 1, 8 * 8 * 4),
    "BlackLevelDeltaH": TagSpec((SRATIONAL,), 1, None), "BlackLevelDeltaV": TagSpec((SRATIONAL,), 1, None),
    "WhiteLevel": TagSpec(_SL, 1, 4), "DefaultScale": TagSpec((RATIONAL,), 2, 2),
    "DefaultCropOrigin": TagSpec((SHORT, LONG, RATIONAL), 2, 2),
    "DefaultCropSize": TagSpec((SHORT, LONG, RATIONAL), 2, 2),
    "ColorMatrix1": TagSpec((SRATIONAL,), 9, 9), "ColorMatrix2": TagSpec((SRATIONAL,), 9, 9),
    "CameraCalibration1": TagSpec((SRATIONAL,), 9, 9), "CameraCalibration2": TagSpec((SRATIONAL,), 9, 9),
    "ForwardMatrix1": TagSpec((SRATIONAL,), 9, 9), "ForwardMatrix2": TagSpec((SRATIONAL,), 9, 9),
    "AnalogBalance": TagSpec((RATIONAL,), 3, 3), "AsShotNeutral": TagSpec((SHORT, RATIONAL), 3, 3),
    "AsShotWhiteXY": TagSpec((RATIONAL,), 2, 2), "BaselineExposure": TagSpec((SRATIONAL,)),
    "BaselineNoise": TagSpec((RATIONAL,)), "CameraSerialNumber": TagSpec(_TEXT, 0, None),
    "CalibrationIlluminant1": TagSpec((SHORT,)), "CalibrationIlluminant2": TagSpec((SHORT,)),
    "ActiveArea": TagSpec(_SL, 4, 4), "MaskedAreas": TagSpec(_SL, 4, 4 * 4),
    "ProfileName": TagSpec(_TEXT, 0, None),
    "OpcodeList1": TagSpec((UNDEFINED,), 4, None), "OpcodeList2": TagSpec((UNDEFINED,), 4, None),
    "OpcodeList3": TagSpec((UNDEFINED,), 4, None), "NoiseProfile": TagSpec((DOUBLE,), 2, 2 * 4),
}


@dataclass(frozen=True)
class RawEntry:
    """One IFD entry as stored: tag, type, count, and where its value bytes are."""

    tag: int
    type: int
    count: int
    value_offset: int  # absolute file position of the value bytes (inside the entry when <= 4 bytes)

    @property
    def nbytes(self) -> int:
        return TIFF_TYPES.get(self.type, ("", 1))[1] * self.count


@dataclass
class RawIfd:
    """The entries of one IFD (``label``: "IFD0", "SubIFD 0", ...)."""

    label: str
    offset: int
    entries: dict[int, RawEntry]


def _type_names(types: tuple[int, ...]) -> str:
    names = [TIFF_TYPES[t][0] for t in types]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]


class _Reader:
    """Bounds-checked little/big-endian reads from an open file."""

    def __init__(self, f, size: int, path: Path):
        self.f, self.size, self.path = f, size, path
        head = self.read(0, 8)
        self.bo = "<" if head[:2] == b"II" else ">"

    def read(self, pos: int, n: int) -> bytes:
        self.f.seek(pos)
        return self.f.read(n)

    def u16(self, pos: int) -> int:
        return struct.unpack(self.bo + "H", self.read(pos, 2))[0]

    def u32(self, pos: int) -> int:
        return struct.unpack(self.bo + "I", self.read(pos, 4))[0]

    def ifd(self, offset: int, label: str) -> RawIfd:
        if offset < 8 or offset + 2 > self.size:
            raise DngError(f"{self.path}: {label}: offset {offset} outside the {self.size}-byte file; "
                           f"expected an image file directory inside it")
        n = self.u16(offset)
        end = offset + 2 + 12 * n + 4
        if n == 0 or end > self.size:
            raise DngError(f"{self.path}: {label}: {n} entries at byte {offset} do not fit the {self.size}-byte "
                           f"file; expected a complete image file directory")
        raw = self.read(offset + 2, 12 * n)
        entries: dict[int, RawEntry] = {}
        for k in range(n):
            tag, typ, count = struct.unpack_from(self.bo + "HHI", raw, 12 * k)
            nbytes = TIFF_TYPES.get(typ, ("", 1))[1] * count
            pos = offset + 2 + 12 * k + 8
            value_offset = pos if nbytes <= 4 else struct.unpack_from(self.bo + "I", raw, 12 * k + 8)[0]
            entries.setdefault(tag, RawEntry(tag, typ, count, value_offset))
        return RawIfd(label, offset, entries)

    def values(self, e: RawEntry) -> list[int]:
        """Integer values of a SHORT / LONG / IFD entry."""
        fmt = {SHORT: "H", LONG: "I", IFD: "I"}[e.type]
        return list(struct.unpack(self.bo + fmt * e.count, self.read(e.value_offset, e.nbytes)))


def scan_ifds(path: Path) -> list[RawIfd] | None:
    """IFD0 and its SubIFDs, raw (None for a file that is not a classic TIFF: tifffile decides).

    Raises
    ------
    DngError
        An IFD outside the file, or a SubIFDs tag of the wrong type or size.
    """
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        if size < 8 or f.read(4) not in (b"II*\x00", b"MM\x00*"):
            return None
        r = _Reader(f, size, path)
        ifd0 = r.ifd(r.u32(4), "IFD0")
        ifds = [ifd0]
        sub = ifd0.entries.get(T["SubIFDs"])
        if sub is not None:
            check_entry(path, "SubIFDs", sub, STRUCTURE_SPECS["SubIFDs"], size, "IFD0")
            for k, off in enumerate(r.values(sub)):
                ifds.append(r.ifd(off, f"SubIFD {k}"))
    return ifds


def check_entry(path: Path, name: str, e: RawEntry, spec: TagSpec, file_size: int, label: str = "") -> None:
    """Type, count and data position of one entry against its :class:`TagSpec`."""
    where = f"{path}: {name}" + (f" ({label})" if label else "")
    if e.type not in spec.types:
        found = TIFF_TYPES.get(e.type, (f"unknown type {e.type}",))[0]
        raise DngError(f"{where}: type {found}; expected {_type_names(spec.types)}")
    if e.count < spec.count_min or (spec.count_max is not None and e.count > spec.count_max):
        want = (f"{spec.count_min}" if spec.count_max == spec.count_min else
                f"{spec.count_min} to {spec.count_max}" if spec.count_max is not None else f"at least {spec.count_min}")
        raise DngError(f"{where}: {e.count} values; expected {want}")
    if e.value_offset + e.nbytes > file_size:
        raise DngError(f"{where}: {e.count} values at byte {e.value_offset} run past the end of the {file_size}-byte "
                       f"file; expected the tag's data inside the file (truncated or corrupt)")


def check_ifds(path: Path, ifds: list[RawIfd], main: RawIfd) -> None:
    """Check the structure tags of every scanned IFD and the DNG tags of IFD0 and the raw IFD ``main``."""
    size = os.path.getsize(path)
    for ifd in ifds:
        label = "" if ifd is main else ifd.label
        for name, spec in STRUCTURE_SPECS.items():
            e = ifd.entries.get(T[name])
            if e is not None:
                check_entry(path, name, e, spec, size, label)
    for ifd in {id(i): i for i in (ifds[0], main)}.values():
        for name, spec in DNG_SPECS.items():
            e = ifd.entries.get(T[name])
            if e is not None:
                check_entry(path, name, e, spec, size)


def main_ifd_index(path: Path, ifds: list[RawIfd]) -> int:
    """Index in ``ifds`` of the raw image: the first with NewSubfileType 0 (DNG 1.7.0.0 chapter 3)."""
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        r = _Reader(f, size, path)
        for k, ifd in enumerate(ifds):
            e = ifd.entries.get(T["NewSubfileType"])
            if e is None:
                return k
            check_entry(path, "NewSubfileType", e, STRUCTURE_SPECS["NewSubfileType"], size, ifd.label)
            if r.values(e)[0] == 0:
                return k
    raise DngError(f"{path}: NewSubfileType: no IFD with value 0 (main image) in IFD0 or its SubIFDs")


def check_raw_entries(path: Path) -> None:
    """Scan IFD0 and its SubIFDs and check every tag simcam uses (see the module docstring)."""
    ifds = scan_ifds(path)
    if ifds is None:
        return
    if T["DNGVersion"] not in ifds[0].entries:
        raise DngError(f"{path}: DNGVersion: tag missing; expected a DNG file (this is a plain TIFF)")
    check_ifds(path, ifds, ifds[main_ifd_index(path, ifds)])
