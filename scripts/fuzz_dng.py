#!/usr/bin/env python
"""Fuzz simcam's DNG reading path with header mutants: every bad file must give one clear error.

Usage::

    python scripts/fuzz_dng.py --mutants 10000 [--seed N] [--timeout 5] [--mem-gb 2] [--workers 2]

Seeds are the DNGs under ``../shared/data/dng`` (when present), the bundled ``examples/data/chart.dng``
and small DNGs simcam writes itself (:func:`simcam.io.sample_dng.make_test_dng`) carrying every tag
path the reader has: OpcodeList1/2/3 with GainMaps, WarpRectilinear, MapTable, MapPolynomial,
DeltaPerRow, ScalePerColumn, bad-pixel lists and TrimBounds; a LinearizationTable; BlackLevelRepeatDim
with per-row / per-column deltas; ActiveArea, DefaultCrop, ForwardMatrix, AsShotWhiteXY, and a 16x16
image LibRaw refuses (the tifffile fallback).

A mutant is a *recipe*: a seed name and a list of edits (:func:`apply_edit`), plain JSON, so that it
can be rebuilt from the seed (the corpus of ``tests/io/fuzz_corpus`` holds such recipes, never the
shared files). Edits change tag types, counts and values (0, negative, huge, NaN, inf, denormal),
opcode payload fields and headers, add tens of thousands of GainMaps, patch bytes and truncate.

Each mutant runs through three targets, each in a child forked from this (warmed-up, single-threaded)
process, at most ``--workers`` at a time: ``simcam.read``, ``simcam.render`` (the ``srgb`` pipeline)
and ``simcam info``. A child may allocate ``--mem-gb`` beyond the address space it inherits
(``RLIMIT_AS``) and use ``--timeout`` CPU seconds (``RLIMIT_CPU``: the machine may be shared, so
wall time would measure the neighbours; a child still running after three times that in wall time is
killed too).
Outcomes: ok, SimcamError (expected for a bad file), other exception (a bug), memory blow-up
(MemoryError or killed), time-out, crash (another signal), stray stderr (anything on file descriptor 2
besides simcam's own one-line error / warnings, or a library warning), bad output (normalised raw or
a render that is not finite, or a render outside [0, 1]), unnamed error (a SimcamError whose message
does not name the file). Each distinct bug is minimised (edits dropped while it still reproduces) and
saved under ``--out`` (recipe ``.json`` and mutant ``.dng``, never committed); ``--corpus DIR`` also
writes the recipes of bugs found on simcam-written seeds there. The script prints a table and exits 1
on any bug.
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # one thread per mutant (before numpy is imported; never on import by the tests)
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "SIMCAM_THREADS"):
        os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import random  # noqa: E402
import re  # noqa: E402
import resource  # noqa: E402
import signal  # noqa: E402
import struct  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Callable  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED_DNG = Path(os.environ.get("SIMCAM_SHARED_DATA", ROOT.parent / "shared" / "data")) / "dng"
CORPUS_DIR = ROOT / "tests" / "io" / "fuzz_corpus"

# ---------------------------------------------------------------------------------------------
# TIFF structure (TIFF 6.0 section 2; DNG Specification 1.7.0.0 chapter 3 "File Structure")
# ---------------------------------------------------------------------------------------------
TYPE_CODE = {"BYTE": 1, "ASCII": 2, "SHORT": 3, "LONG": 4, "RATIONAL": 5, "SBYTE": 6, "UNDEFINED": 7,
             "SSHORT": 8, "SLONG": 9, "SRATIONAL": 10, "FLOAT": 11, "DOUBLE": 12, "IFD": 13}
TYPE_SIZE = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4}
_INT_FORMAT = {1: "B", 3: "H", 4: "I", 5: "I", 6: "b", 8: "h", 9: "i", 10: "i", 13: "I"}
_FLOAT_FORMAT = {11: "f", 12: "d"}


def _tag_codes() -> dict[str, int]:
    from simcam.io.dng import T

    return {**T, "Software": 305, "DNGPrivateData": 50740, "XMP": 700}


def tag_code(tag: int | str) -> int:
    """A tag number from its number or its DNG / TIFF name (``"BlackLevelRepeatDim"``)."""
    return int(tag) if isinstance(tag, int) or str(tag).isdigit() else _tag_codes()[str(tag)]


def tag_name(code: int) -> str:
    for name, c in _tag_codes().items():
        if c == code:
            return name
    return str(code)


@dataclass
class Entry:
    """One 12-byte IFD entry: tag, type, count and the 4-byte value-or-offset field."""

    tag: int
    type: int
    count: int
    pos: int
    field: bytes


@dataclass
class Ifd:
    """An IFD: where it is, where the pointer to it is stored, its entries by tag."""

    name: str
    offset: int
    pointer_pos: int
    entries: dict[int, Entry] = field(default_factory=dict)
    next_offset: int = 0


class Layout:
    """The IFDs of a classic TIFF: IFD0, its SubIFDs (``sub0``...), the EXIF IFD and IFD1.

    ``"main"`` names the IFD of the raw image (NewSubfileType 0; DNG 1.7.0.0 chapter 3).
    Parsing is lenient (a mutant may be broken): entries are kept as they are stored.
    """

    def __init__(self, data: bytes):
        self.data = data
        if data[:4] not in (b"II*\x00", b"MM\x00*"):
            raise ValueError("not a classic TIFF")
        self.bo = "<" if data[:2] == b"II" else ">"
        self.ifds: dict[str, Ifd] = {}
        ifd0 = self._read_ifd("ifd0", self.u32(4), 4)
        sub = ifd0.entries.get(330)
        if sub is not None:
            if sub.count == 1:
                ptrs = [sub.pos + 8]
            else:
                base = struct.unpack(self.bo + "I", sub.field)[0]
                ptrs = [base + 4 * i for i in range(min(sub.count, 16))]
            for i, p in enumerate(ptrs):
                if p + 4 <= len(data):
                    self._read_ifd(f"sub{i}", self.u32(p), p)
        exif = ifd0.entries.get(34665)
        if exif is not None:
            self._read_ifd("exif", self.u32(exif.pos + 8), exif.pos + 8)
        if ifd0.next_offset:
            self._read_ifd("ifd1", ifd0.next_offset, ifd0.offset + 2 + 12 * len(ifd0.entries))

    def u32(self, pos: int) -> int:
        return struct.unpack_from(self.bo + "I", self.data, pos)[0]

    def _read_ifd(self, name: str, off: int, pointer_pos: int) -> Ifd:
        ifd = Ifd(name, off, pointer_pos)
        if off + 2 > len(self.data) or off < 8:
            return ifd
        (n,) = struct.unpack_from(self.bo + "H", self.data, off)
        n = min(n, (len(self.data) - off - 2) // 12)
        for k in range(n):
            pos = off + 2 + 12 * k
            tag, typ, count = struct.unpack_from(self.bo + "HHI", self.data, pos)
            ifd.entries.setdefault(tag, Entry(tag, typ, count, pos, self.data[pos + 8:pos + 12]))
        end = off + 2 + 12 * n
        ifd.next_offset = self.u32(end) if end + 4 <= len(self.data) else 0
        self.ifds[name] = ifd
        return ifd

    def ifd(self, name: str) -> Ifd:
        if name == "main":
            for cand in ["ifd0"] + sorted(k for k in self.ifds if k.startswith("sub")):
                nst = self.ifds.get(cand, Ifd("", 0, 0)).entries.get(254)
                if cand in self.ifds and (nst is None or self.values(nst)[:1] == [0]):
                    return self.ifds[cand]
            return self.ifds["ifd0"]
        return self.ifds[name]

    def value_bytes(self, e: Entry) -> bytes:
        size = TYPE_SIZE.get(e.type, 1) * e.count
        if size <= 4:
            return e.field[:size]
        off = struct.unpack(self.bo + "I", e.field)[0]
        return self.data[off:off + min(size, len(self.data))]

    def values(self, e: Entry) -> list:
        raw = self.value_bytes(e)
        if e.type in _FLOAT_FORMAT or e.type in _INT_FORMAT:
            fmt = _FLOAT_FORMAT.get(e.type) or _INT_FORMAT[e.type]
            n = len(raw) // struct.calcsize(fmt)
            return list(struct.unpack(self.bo + fmt * n, raw[:n * struct.calcsize(fmt)]))
        return list(raw)


def _pack_values(typ: int, values: list, bo: str) -> bytes:
    """Values of TIFF type ``typ`` (rationals: the flat list of numerator, denominator parts).

    Integers wrap around (a mutant may hold -1 in a SHORT); float32 overflows to inf.
    """
    if typ in _FLOAT_FORMAT:
        vals = [float(v) for v in values]
        if typ == 11:
            with np.errstate(over="ignore"):  # float32 overflows to inf on purpose
                return np.asarray(vals, dtype=np.float64).astype(bo + "f4").tobytes() if vals else b""
        return struct.pack(bo + "d" * len(vals), *vals)
    fmt = _INT_FORMAT.get(typ, "B")
    bits = 8 * struct.calcsize(fmt)
    out = []
    for v in values:
        v = int(v) % (1 << bits)
        if fmt.islower() and v >= 1 << (bits - 1):
            v -= 1 << bits
        out.append(v)
    return struct.pack(bo + fmt * len(out), *out)


def _rewrite_ifd(data: bytes, lay: Layout, ifd: Ifd, entries: dict[int, tuple[int, int, bytes]]) -> bytes:
    """Append a new copy of ``ifd`` holding ``entries`` (tag -> type, count, value bytes) and point to it.

    The old IFD is left in place (unreferenced); out-of-line values follow the new IFD, word aligned.
    """
    out = bytearray(data)
    if len(out) % 2:
        out += b"\0"
    bo = lay.bo
    codes = sorted(entries)
    ifd_off = len(out)
    blob_start = ifd_off + 2 + 12 * len(codes) + 4
    head, blob = [struct.pack(bo + "H", len(codes))], bytearray()
    for code in codes:
        typ, count, raw = entries[code]
        if TYPE_SIZE.get(typ, 1) * count <= 4 and len(raw) <= 4:
            fld = raw.ljust(4, b"\0")
        else:
            if len(blob) % 2:
                blob += b"\0"
            fld = struct.pack(bo + "I", blob_start + len(blob))
            blob += raw
        head.append(struct.pack(bo + "HHI", code, typ, count % (1 << 32)) + fld)
    head.append(struct.pack(bo + "I", ifd.next_offset))
    out += b"".join(head) + bytes(blob)
    struct.pack_into(bo + "I", out, ifd.pointer_pos, ifd_off)
    return bytes(out)


def _entries_of(lay: Layout, ifd: Ifd) -> dict[int, tuple[int, int, bytes]]:
    return {t: (e.type, e.count, lay.value_bytes(e)) for t, e in ifd.entries.items()}


# ---------------------------------------------------------------------------------------------
# edits: each a JSON dict; apply_edit(bytes, edit) -> bytes
# ---------------------------------------------------------------------------------------------
#: Offsets and struct formats of the GainMap parameters inside its payload (DNG 1.7.0.0 sec. 7, opcode 9).
GAIN_MAP_FIELDS = {"Top": (0, ">I"), "Left": (4, ">I"), "Bottom": (8, ">I"), "Right": (12, ">I"),
                   "Plane": (16, ">I"), "Planes": (20, ">I"), "RowPitch": (24, ">I"), "ColPitch": (28, ">I"),
                   "MapPointsV": (32, ">I"), "MapPointsH": (36, ">I"), "MapSpacingV": (40, ">d"),
                   "MapSpacingH": (48, ">d"), "MapOriginV": (56, ">d"), "MapOriginH": (64, ">d"),
                   "MapPlanes": (72, ">I")}


def _num(v: Any) -> Any:
    """JSON numbers, and "nan" / "inf" / "-inf" strings (plain JSON has no NaN)."""
    return float(v) if isinstance(v, str) else v


def _opcode_spans(blob: bytes) -> list[tuple[int, int, int]]:
    """(header position, payload position, payload size) of each opcode of a list (lenient)."""
    spans, pos = [], 4
    count = struct.unpack_from(">I", blob, 0)[0] if len(blob) >= 4 else 0
    for _ in range(count):
        if pos + 16 > len(blob):
            break
        n = struct.unpack_from(">I", blob, pos + 12)[0]
        spans.append((pos, pos + 16, n))
        pos += 16 + n
        if pos > len(blob):
            break
    return spans


def _opcode_list_tag(lay: Layout, k: int) -> tuple[Ifd, Entry] | None:
    code = 51008 if k == 1 else 51009 if k == 2 else 51022
    for name in ("main", "ifd0"):
        ifd = lay.ifd(name)
        if code in ifd.entries:
            return ifd, ifd.entries[code]
    return None


def _set_tag(data: bytes, lay: Layout, ifd: Ifd, code: int, typ: int, count: int, raw: bytes) -> bytes:
    entries = _entries_of(lay, ifd)
    entries[code] = (typ, count, raw)
    return _rewrite_ifd(data, lay, ifd, entries)


def tiny_gain_maps(n: int, *, bottom: int = 1 << 30, right: int = 1 << 30) -> bytes:
    """An opcode list of ``n`` one-point GainMaps (gain 1.0, rows and columns 0..bottom/right, pitch 2)."""
    payload = struct.pack(">10I4dI", 0, 0, bottom, right, 0, 1, 2, 2, 1, 1, 1.0, 1.0, 0.0, 0.0, 1) + \
        struct.pack(">f", 1.0)
    op = struct.pack(">I4BII", 9, 1, 3, 0, 0, 0, len(payload)) + payload
    return struct.pack(">I", n) + op * n


def apply_edit(data: bytes, edit: dict) -> bytes:
    """Apply one recipe edit to the bytes of a DNG (see the module docstring for the kinds)."""
    op = edit["op"]
    if op == "truncate":
        return data[:max(0, int(edit["size"]))]
    if op == "patch":
        raw = bytes.fromhex(edit["hex"])
        off = int(edit["offset"])
        out = bytearray(data)
        out[off:off + len(raw)] = raw
        return bytes(out[:max(len(data), off)]) if off <= len(data) else bytes(data)
    lay = Layout(data)
    if op in ("set", "delete", "retype"):
        ifd = lay.ifd(edit.get("ifd", "main"))
        code = tag_code(edit["tag"])
        if op == "delete":
            entries = _entries_of(lay, ifd)
            entries.pop(code, None)
            return _rewrite_ifd(data, lay, ifd, entries)
        if op == "retype":  # change the entry's type / count in place, keep its 4-byte field
            e = ifd.entries.get(code)
            if e is None:
                return data
            out = bytearray(data)
            typ = TYPE_CODE.get(edit.get("type"), edit.get("type", e.type))
            struct.pack_into(lay.bo + "HI", out, e.pos + 2, int(typ) % 65536, int(edit.get("count", e.count)) % (1 << 32))
            return bytes(out)
        typ = int(TYPE_CODE.get(edit["type"], edit["type"]))
        if "hex" in edit:
            raw = bytes.fromhex(edit["hex"])
        elif "text" in edit:
            raw = str(edit["text"]).encode("latin-1") + b"\0"
        else:
            raw = _pack_values(typ, [_num(v) for v in edit["values"]], lay.bo)
        count = int(edit.get("count", len(raw) // TYPE_SIZE.get(typ, 1)))
        return _set_tag(data, lay, ifd, code, typ, count, raw)
    if op in ("opcode", "opcode_header", "gainmaps"):
        k = int(edit["list"])
        found = _opcode_list_tag(lay, k)
        if op == "gainmaps":
            ifd = found[0] if found else lay.ifd("main")
            blob = tiny_gain_maps(int(edit["n"]))
            return _set_tag(data, lay, ifd, 51008 if k == 1 else 51009 if k == 2 else 51022, 7, len(blob), blob)
        if found is None:
            return data
        ifd, entry = found
        blob = bytearray(lay.value_bytes(entry))
        spans = _opcode_spans(bytes(blob))
        if op == "opcode_header":
            fld = edit["field"]
            if fld == "count":
                struct.pack_into(">I", blob, 0, int(edit["value"]) % (1 << 32))
            elif spans:
                hdr = spans[int(edit.get("index", 0)) % len(spans)][0]
                off = {"id": 0, "version": 4, "flags": 8, "size": 12}[fld]
                struct.pack_into(">I", blob, hdr + off, int(edit["value"]) % (1 << 32))
        elif spans:
            _, start, n = spans[int(edit.get("index", 0)) % len(spans)]
            off, fmt = GAIN_MAP_FIELDS[edit["field"]] if "field" in edit else (int(edit["offset"]), edit["format"])
            raw = _pack_values(12 if fmt.endswith("d") else 11 if fmt.endswith("f") else
                               {">I": 4, ">i": 9}[fmt], [_num(edit["value"])], ">")
            if start + off + len(raw) <= len(blob):
                blob[start + off:start + off + len(raw)] = raw
        return _set_tag(data, lay, ifd, entry.tag, entry.type, len(blob), bytes(blob))
    raise ValueError(f"unknown edit {op!r}")


def build_mutant(seed_bytes: bytes, edits: list[dict]) -> bytes:
    """The mutant of a seed: its edits applied in order (an edit on an unparseable file is skipped)."""
    data = seed_bytes
    for e in edits:
        try:
            data = apply_edit(data, e)
        except (ValueError, KeyError, IndexError, struct.error):
            continue
    return data


# ---------------------------------------------------------------------------------------------
# seeds
# ---------------------------------------------------------------------------------------------
def _area(t=0, l=0, b=0, r=0, plane=0, planes=1, rp=1, cp=1) -> bytes:
    return struct.pack(">4i4I", t, l, b, r, plane, planes, rp, cp)


def _opcode(oid: int, payload: bytes, flags: int = 0):
    from simcam.frame import Opcode

    return Opcode(id=oid, version=(1, 3, 0, 0), flags=flags, payload=payload)


def _gain_map_planes(h: int, w: int, planes: int):
    """One GainMap of 3 x 4 points over ``planes`` planes (OpcodeList3 on RGB)."""
    from simcam.frame import GainMap
    from simcam.io.opcodes import gain_map_opcode

    gains = (1.0 + 0.1 * np.arange(3 * 4 * planes).reshape(3, 4, planes) / (12 * planes)).astype(np.float32)
    return gain_map_opcode(GainMap(top=0, left=0, bottom=h, right=w, plane=0, planes=planes, row_pitch=1,
                                   col_pitch=1, map_spacing_v=0.5, map_spacing_h=1 / 3, map_origin_v=0.0,
                                   map_origin_h=0.0, gains=gains))


def _seed_plain(path: Path) -> None:
    from simcam.io.sample_dng import make_test_dng

    make_test_dng(path, 32, 32)


def _seed_tiny(path: Path) -> None:
    """16 x 16: LibRaw refuses it, the reader falls back to tifffile."""
    from simcam.io.sample_dng import make_test_dng

    make_test_dng(path, 16, 16, cfa="GRBG")


def _seed_gainmaps(path: Path) -> None:
    """ActiveArea, four OpcodeList2 GainMaps (one per Bayer phase), DefaultCrop."""
    from simcam.io.sample_dng import make_test_dng, radial_gain_maps

    make_test_dng(path, 48, 64, active_area=(2, 2, 46, 62), opcode_list2=radial_gain_maps(44, 60),
                  default_crop_origin=(2.0, 2.0), default_crop_size=(56.0, 40.0))


def _seed_opcodes(path: Path) -> None:
    """Every opcode simcam applies, in the list the DNG SDK applies it."""
    from simcam.io.sample_dng import make_test_dng, radial_gain_maps

    h = w = 40
    table = np.minimum(np.arange(1024) * 2, 65535).astype(">u2").tobytes()
    list1 = [_opcode(4, struct.pack(">2I", 0, 0)),
             _opcode(7, _area(0, 0, h, w) + struct.pack(">I", 1024) + table)]
    list2 = [_opcode(10, _area() + struct.pack(">I", h) + np.full(h, 0.001, ">f4").tobytes()),
             _opcode(13, _area(rp=1, cp=1) + struct.pack(">I", w) + np.full(w, 1.01, ">f4").tobytes()),
             _opcode(8, _area(0, 0, h, w, rp=2) + struct.pack(">I", 2) + struct.pack(">3d", 0.0, 1.0, 0.01)),
             _opcode(5, struct.pack(">3I", 0, 2, 1) + struct.pack(">4I", 3, 4, 10, 11) + struct.pack(">4I", 20, 20, 22, 23)),
             *radial_gain_maps(h, w, points=(3, 3))]
    warp = struct.pack(">I", 3) + struct.pack(">18d", *([1.001, 0.001, 0, 0, 0.0001, 0.0] * 3)) + struct.pack(">2d", 0.5, 0.5)
    list3 = [_opcode(1, warp), _gain_map_planes(h, w, 3), _opcode(6, struct.pack(">4i", 0, 0, h, w)),
             _opcode(3, struct.pack(">I", 0), flags=1)]
    make_test_dng(path, h, w, opcode_list1=list1, opcode_list2=list2, opcode_list3=list3)


def _seed_levels(path: Path) -> None:
    """LinearizationTable, a 2 x 2 BlackLevel pattern (BlackLevelRepeatDim) and BlackLevelDeltaH/V."""
    from simcam.io.sample_dng import make_test_dng, synthetic_meta, synthetic_mosaic

    h = w = 32
    data = synthetic_mosaic(h, w, synthetic_meta(black=64.0, white=4095.0))
    table = np.round(np.arange(4096) * 1.5 + (np.arange(4096) / 4095.0) ** 2 * 100).astype(np.float64)
    make_test_dng(path, h, w, data=data, linearization_table=table,
                  black_level=np.array([[96.0, 100.0], [98.0, 94.0]]), white=6242.0,
                  black_level_delta_h=np.linspace(-1, 1, w), black_level_delta_v=np.linspace(0, 2, h))


def _seed_colour(path: Path) -> None:
    """ActiveArea, DefaultCrop, Orientation 6, ForwardMatrix, CameraCalibration, AsShotWhiteXY, 3 noise pairs."""
    from simcam.io.sample_dng import make_test_dng

    eye = np.eye(3)
    fm = np.array([[0.6, 0.3, 0.05], [0.25, 0.7, 0.05], [0.05, 0.05, 0.75]])
    make_test_dng(path, 36, 44, active_area=(2, 4, 34, 42), default_crop_origin=(1.0, 2.0),
                  default_crop_size=(36.0, 30.0), orientation=6, forward_matrix1=fm, forward_matrix2=fm,
                  camera_calibration1=eye * 1.01, camera_calibration2=eye, analog_balance=np.ones(3),
                  as_shot_neutral=None, as_shot_white_xy=np.array([0.3457, 0.3585]), baseline_exposure=0.5,
                  noise_profile=np.array([[2e-4, 1e-6], [2.1e-4, 1e-6], [2.2e-4, 1e-6]]))


#: Seeds simcam writes (name -> builder), deterministic bytes.
WRITTEN_SEEDS: dict[str, Callable[[Path], None]] = {
    "plain": _seed_plain, "tiny": _seed_tiny, "gainmaps": _seed_gainmaps, "opcodes": _seed_opcodes,
    "levels": _seed_levels, "colour": _seed_colour,
}


def seed_bytes(name: str, workdir: Path) -> bytes:
    """The bytes of seed ``name``: a simcam-written seed, ``chart`` (examples/data) or ``shared:<file>``."""
    if name == "chart":
        return (ROOT / "examples" / "data" / "chart.dng").read_bytes()
    if name.startswith("shared:"):
        return (SHARED_DNG / name.split(":", 1)[1]).read_bytes()
    path = Path(workdir) / f"seed-{name}.dng"
    if not path.exists():
        WRITTEN_SEEDS[name](path)
    return path.read_bytes()


def available_seeds() -> list[str]:
    names = list(WRITTEN_SEEDS) + ["chart"]
    if SHARED_DNG.is_dir():
        names += [f"shared:{p.name}" for p in sorted(SHARED_DNG.iterdir())
                  if p.suffix.lower() in (".dng", ".gpr") and p.is_file()]
    return names


# ---------------------------------------------------------------------------------------------
# mutations
# ---------------------------------------------------------------------------------------------
INF, NAN = float("inf"), float("nan")
SPECIAL_INTS = [0, 1, 2, 3, -1, -2, 7, 8, 9, 15, 16, 17, 21, 22, 255, 256, 4095, 32767, 65535, 65536,
                2 ** 24, 2 ** 31 - 1, 2 ** 31, 2 ** 32 - 1]
SPECIAL_FLOATS = [0.0, -0.0, 1.0, -1.0, 0.5, 2.0, NAN, INF, -INF, 5e-324, 2.2250738585072014e-308, 1e-300,
                  1e300, -1e300, 3.4028234663852886e38, 1.4e-45, 65535.0, 1e9]
ALL_TYPES = list(TYPE_SIZE) + [0, 14, 16, 99, 65535]
#: Tags whose absurd values the fuzzer tries on purpose (sizes, repeat patterns, crops, tables).
ABSURD = {
    "ImageWidth": [0, 1, 2, 65000, 65001, 65535, 2 ** 31, 2 ** 32 - 1],
    "ImageLength": [0, 1, 2, 65000, 65001, 65535, 2 ** 31, 2 ** 32 - 1],
    "RowsPerStrip": [0, 1, 2 ** 32 - 1],
    "BitsPerSample": [0, 1, 8, 10, 12, 14, 17, 32, 65535],
    "TileWidth": [0, 1, 16, 65535, 2 ** 32 - 1], "TileLength": [0, 1, 16, 2 ** 32 - 1],
    "BlackLevelRepeatDim": [[0, 0], [1, 0], [8, 8], [9, 1], [2, 65535], [65535, 65535]],
    "CFARepeatPatternDim": [[0, 0], [3, 3], [2, 65535], [65535, 65535]],
    "ActiveArea": [[0, 0, 0, 0], [10, 10, 5, 5], [0, 0, 65535, 65535], [2 ** 31, 0, 2 ** 32 - 1, 1], [0, 0, 1, 1],
                   [0, 0, 2, 2], [2, 2, 4, 6], [1, 1, 9, 9]],
    "DefaultCropSize": [[0, 0], [1, 1], [2, 2], [65535, 1], [2 ** 32 - 1, 2 ** 32 - 1]],
    "DefaultCropOrigin": [[0, 0], [1, 1], [65535, 0], [2 ** 32 - 1, 2 ** 32 - 1]],
    "WhiteLevel": [0, 1, 63, 64, 65, 65535, 2 ** 32 - 1], "BlackLevel": [0, 1023, 65535, 2 ** 32 - 1],
    "LinearizationTable": [[0], [65535], [0, 65535], [7] * 300],
    "CFAPattern": [[0, 0, 0, 0], [0, 1, 1, 3], [2, 1, 1, 0], [9, 9, 9, 9]],
    "SamplesPerPixel": [0, 3, 65535], "Orientation": [0, 9, 65535], "CFALayout": [0, 2],
    "Compression": [0, 6, 7, 8, 9, 34892, 65535], "PhotometricInterpretation": [0, 2, 34892],
    "SubIFDs": [[0], [8], [2 ** 32 - 1]],
}


def _values_of(lay: Layout, e: Entry) -> list:
    try:
        return lay.values(e)
    except (struct.error, ValueError):
        return []


def _special_value(rng: random.Random, typ: int):
    return rng.choice(SPECIAL_FLOATS if typ in _FLOAT_FORMAT else SPECIAL_INTS)


def _mutate_value(rng: random.Random, lay: Layout, ifd_name: str) -> dict:
    """Set an existing (or a known, absent) tag to a changed type / count / values."""
    ifd = lay.ifd(ifd_name)
    known = [c for c in ifd.entries if tag_name(c) != str(c)]
    if known and rng.random() < 0.85:
        code = rng.choice(known)
    elif rng.random() < 0.5 or not ifd.entries:
        code = tag_code(rng.choice(sorted(_tag_codes())))
    else:
        code = rng.choice(sorted(ifd.entries))
    e = ifd.entries.get(code)
    typ = e.type if e is not None and e.type in TYPE_SIZE and rng.random() < 0.7 else \
        rng.choice([1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12])
    vals = _values_of(lay, e) if e is not None and e.type == typ else []
    if typ in (2, 7, 1) and rng.random() < 0.3:
        raw = bytes(lay.value_bytes(e)) if e is not None else b"\x00\x01\x02\x03"
        raw = bytearray(raw or b"\x00")
        raw[rng.randrange(len(raw))] = rng.randrange(256)
        edit = {"op": "set", "ifd": ifd_name, "tag": tag_name(code), "type": typ, "hex": bytes(raw[:4096]).hex()}
    else:
        n = max(len(vals), 1) if typ not in (5, 10) else max(len(vals), 2)
        vals = list(vals) or [_special_value(rng, typ) for _ in range(n)]
        how = rng.random()
        if how < 0.5:
            vals[rng.randrange(len(vals))] = _special_value(rng, typ)
        elif how < 0.7:
            v = _special_value(rng, typ)
            vals = [v] * len(vals)
        elif how < 0.85:
            vals = vals[:rng.randrange(len(vals) + 1)]
        else:
            vals = vals + [_special_value(rng, typ) for _ in range(rng.choice([1, 2, 9, 100]))]
        if typ not in _FLOAT_FORMAT:
            vals = [int(v) if math.isfinite(v) else 0 for v in vals]
        edit = {"op": "set", "ifd": ifd_name, "tag": tag_name(code), "type": typ,
                "values": [v if not (isinstance(v, float) and not math.isfinite(v)) else str(v) for v in vals]}
    if rng.random() < 0.1:
        edit["count"] = rng.choice([0, 1, 2 ** 16, 2 ** 31 - 1, 2 ** 32 - 1])
    return edit


def _mutate_absurd(rng: random.Random, lay: Layout) -> dict:
    name = rng.choice(sorted(ABSURD))
    v = rng.choice(ABSURD[name])
    vals = v if isinstance(v, list) else [v]
    typ = 4 if max(vals) > 65535 or name in ("ActiveArea", "SubIFDs") else 1 if name == "CFAPattern" else 3
    return {"op": "set", "ifd": "ifd0" if name == "SubIFDs" else "main", "tag": name,
            "type": typ, "values": [x % (1 << 32) for x in vals]}


def _mutate_opcode(rng: random.Random, lay: Layout) -> dict | None:
    lists = [k for k in (1, 2, 3) if _opcode_list_tag(lay, k) is not None]
    if not lists:
        return None
    k = rng.choice(lists)
    _, entry = _opcode_list_tag(lay, k)
    blob = lay.value_bytes(entry)
    spans = _opcode_spans(blob)
    if not spans or rng.random() < 0.15:
        fld = rng.choice(["id", "flags", "size", "count", "version"])
        return {"op": "opcode_header", "list": k, "index": rng.randrange(max(len(spans), 1)), "field": fld,
                "value": rng.choice(SPECIAL_INTS) if fld != "id" else rng.choice([0, 1, 4, 7, 9, 14, 15, 99])}
    index = rng.randrange(len(spans))
    hdr, start, n = spans[index]
    oid = struct.unpack_from(">I", blob, hdr)[0]
    if oid == 9 and rng.random() < 0.7:
        fld = rng.choice(sorted(GAIN_MAP_FIELDS))
        off, fmt = GAIN_MAP_FIELDS[fld]
        value = rng.choice(SPECIAL_FLOATS) if fmt.endswith("d") else rng.choice(SPECIAL_INTS)
        if fmt.endswith("d") and rng.random() < 0.5:  # map gains (float32) after the header
            points = max((n - 76) // 4, 0)
            if points:
                return {"op": "opcode", "list": k, "index": index, "offset": 76 + 4 * rng.randrange(points),
                        "format": ">f", "value": _json_float(rng.choice(SPECIAL_FLOATS))}
        return {"op": "opcode", "list": k, "index": index, "field": fld, "value": _json_float(value)}
    if n < 4:
        return None
    fmt = rng.choice([">I", ">i", ">f", ">d"])
    size = 8 if fmt == ">d" else 4
    if n < size:
        fmt, size = ">I", 4
    off = 4 * rng.randrange((n - size) // 4 + 1)
    value = rng.choice(SPECIAL_FLOATS) if fmt in (">f", ">d") else rng.choice(SPECIAL_INTS)
    return {"op": "opcode", "list": k, "index": index, "offset": off, "format": fmt, "value": _json_float(value)}


def _json_float(v):
    return str(v) if isinstance(v, float) and not math.isfinite(v) else v


def _mutate_bytes(rng: random.Random, lay: Layout, size: int) -> dict:
    """Patch a few bytes of an IFD entry, of a tag's data, or of the first 64 KB."""
    r = rng.random()
    entries = [e for ifd in lay.ifds.values() for e in ifd.entries.values()]
    if r < 0.4 and entries:
        e = rng.choice(entries)
        off = e.pos + rng.randrange(12)
    elif r < 0.7 and entries:
        e = rng.choice(entries)
        off = struct.unpack(lay.bo + "I", e.field)[0] if TYPE_SIZE.get(e.type, 1) * e.count > 4 else e.pos + 8
        off = min(off + rng.randrange(16), max(size - 1, 0))
    else:
        off = rng.randrange(min(size, 65536))
    n = rng.choice([1, 1, 2, 4, 8])
    fill = rng.choice(["random", "ff", "00"])
    raw = bytes(rng.randrange(256) for _ in range(n)) if fill == "random" else bytes.fromhex(fill * n)
    return {"op": "patch", "offset": off, "hex": raw.hex()}


def _mutate_truncate(rng: random.Random, lay: Layout, size: int) -> dict:
    r = rng.random()
    if r < 0.4:
        cut = rng.randrange(min(size, 4096))
    elif r < 0.7:
        cut = size - rng.randrange(1, min(size, 4096))
    else:
        cut = rng.randrange(size)
    return {"op": "truncate", "size": cut}


def make_edits(rng: random.Random, seed: bytes) -> list[dict]:
    """One to three random edits of a seed (byte patches and truncations last)."""
    lay = Layout(seed)
    names = list(lay.ifds)
    edits: list[dict] = []
    for _ in range(rng.choices([1, 2, 3], weights=[6, 3, 1])[0]):
        kind = rng.choices(["value", "retype", "delete", "absurd", "opcode", "gainmaps", "patch", "truncate"],
                           weights=[30, 8, 6, 14, 22, 2, 10, 8])[0]
        ifd_name = rng.choices(["main", "ifd0", rng.choice(names)], weights=[7, 2, 1])[0]
        edit = None
        if kind == "value":
            edit = _mutate_value(rng, lay, ifd_name)
        elif kind == "retype":
            ifd = lay.ifd(ifd_name)
            if ifd.entries:
                code = rng.choice(sorted(ifd.entries))
                e = ifd.entries[code]
                if rng.random() < 0.5:
                    edit = {"op": "retype", "ifd": ifd_name, "tag": tag_name(code), "type": rng.choice(ALL_TYPES)}
                else:
                    edit = {"op": "retype", "ifd": ifd_name, "tag": tag_name(code), "count": rng.choice(
                        [0, 1, max(e.count - 1, 0), e.count + 1, 2 * e.count, 2 ** 16, 2 ** 31, 2 ** 32 - 1])}
        elif kind == "delete":
            ifd = lay.ifd(ifd_name)
            if ifd.entries:
                edit = {"op": "delete", "ifd": ifd_name, "tag": tag_name(rng.choice(sorted(ifd.entries)))}
        elif kind == "absurd":
            edit = _mutate_absurd(rng, lay)
        elif kind == "opcode":
            edit = _mutate_opcode(rng, lay)
        elif kind == "gainmaps":
            edit = {"op": "gainmaps", "list": rng.choice([1, 2, 3]), "n": rng.choice([2000, 20000, 50000])}
        elif kind == "patch":
            edit = _mutate_bytes(rng, lay, len(seed))
        else:
            edit = _mutate_truncate(rng, lay, len(seed))
        if edit is not None:
            edits.append(edit)
    edits.sort(key=lambda e: e["op"] in ("patch", "truncate"))
    return edits


# ---------------------------------------------------------------------------------------------
# targets, run in forked children
# ---------------------------------------------------------------------------------------------
TARGETS = ("read", "render", "info")
BUG_OUTCOMES = ("other", "memory", "timeout", "crash", "stray", "bad_output", "unnamed")
COLUMNS = [("ok", "ok"), ("simcam_error", "SimcamError"), ("other", "other exc"), ("memory", "memory"),
           ("timeout", "time-out"), ("crash", "crash"), ("stray", "stray stderr"), ("bad_output", "bad output"),
           ("unnamed", "unnamed err")]


def _innermost(tb) -> str:
    frames = traceback.extract_tb(tb)
    if not frames:
        return "?"
    own = [f for f in frames if "/simcam/" in f.filename] or frames
    f = own[-1]
    return f"{Path(f.filename).name}:{f.lineno}"


def run_target(target: str, path: Path) -> dict:
    """Run one target in this process; the outcome as a dict (see :data:`COLUMNS`)."""
    import warnings

    import simcam
    from simcam.cli import main as cli_main
    from simcam.errors import SimcamWarning

    res: dict[str, Any] = {"outcome": "ok"}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if target == "read":
                frame = simcam.read(path)
                if not np.all(np.isfinite(frame.data)):
                    res.update(outcome="bad_output", message="normalised raw holds NaN or infinity")
            elif target == "render":
                rgb = np.asarray(simcam.render(path))
                if not np.all(np.isfinite(rgb)) or rgb.size == 0 or rgb.min() < 0 or rgb.max() > 1:
                    res.update(outcome="bad_output", message="sRGB render not finite in [0, 1]")
            else:
                rc = cli_main(["info", str(path)])
                res.update(outcome={0: "ok", 2: "simcam_error"}.get(rc, "other"), rc=rc)
        except simcam.SimcamError as exc:
            res.update(outcome="simcam_error", type=type(exc).__name__, message=str(exc))
        except MemoryError as exc:
            res.update(outcome="memory", type="MemoryError", message=str(exc)[:200], where=_innermost(exc.__traceback__))
        except Exception as exc:  # noqa: BLE001 - a bug: recorded, not raised
            res.update(outcome="other", type=type(exc).__name__, message=str(exc).split("\n")[0][:300],
                       where=_innermost(exc.__traceback__))
    stray = [f"{w.category.__name__}: {w.message}" for w in caught if not issubclass(w.category, SimcamWarning)]
    res["warnings"] = stray[:3]
    return res


def _child_main(target: str, path: Path, res_path: Path, err_path: Path, mem_bytes: int, cpu_s: int) -> None:
    """Body of a forked child: limits, stderr to a file, stdout to /dev/null, run, write the result."""
    code = 0
    try:
        resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu_s, cpu_s + 1))  # SIGXCPU after cpu_s CPU seconds
        os.environ["SIMCAM_THREADS"] = "1"  # simcam's row bands: one thread (it reads this per call)
        err = os.open(err_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(err, 2)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        # Python-level streams on the descriptors (under pytest they are capture objects)
        sys.stdout = open(1, "w", closefd=False)
        sys.stderr = open(2, "w", buffering=1, closefd=False)
        t0 = time.perf_counter()
        res = run_target(target, path)
        res["seconds"] = time.perf_counter() - t0  # wall time of the target alone (no fork, no import)
        sys.stdout.flush()
        sys.stderr.flush()
        res_path.write_text(json.dumps(res))
    except BaseException:  # noqa: BLE001 - the child must always reach os._exit
        code = 3
    finally:
        os._exit(code)


@dataclass
class Task:
    mutant: int
    target: str
    path: Path
    res_path: Path
    err_path: Path
    start: float = 0.0
    pid: int = 0
    timed_out: bool = False
    cpu_limit: int = 0


def _classify(task: Task, status: int, rusage, base_rss_kb: int) -> dict:
    """The outcome of a finished child: its result file, its stderr, how it ended."""
    res: dict[str, Any] = {}
    cpu = rusage.ru_utime + rusage.ru_stime if rusage is not None else 0.0
    if task.timed_out:
        res = {"outcome": "timeout", "message": "killed after the wall-clock limit"}
    elif os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig == signal.SIGXCPU or (sig == signal.SIGKILL and cpu >= task.cpu_limit):
            res = {"outcome": "timeout", "message": f"over the CPU-time limit ({cpu:.1f} s)"}
        else:
            res = {"outcome": "memory" if sig == signal.SIGKILL else "crash",
                   "message": f"killed by signal {signal.Signals(sig).name}"}
    elif task.res_path.exists():
        try:
            res = json.loads(task.res_path.read_text())
        except ValueError:
            res = {"outcome": "crash", "message": "unreadable result"}
    else:
        res = {"outcome": "crash", "message": f"exit status {os.WEXITSTATUS(status)} without a result"}
    err = task.err_path.read_text(errors="replace") if task.err_path.exists() else ""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if task.target == "info":
        own = [ln for ln in lines if ln.startswith(("simcam info: error: ", "simcam info: warning: "))]
        stray = [ln for ln in lines if ln not in own]
        errors = [ln for ln in own if ln.startswith("simcam info: error: ")]
        if res.get("outcome") == "simcam_error" and errors:
            res["message"] = errors[-1][len("simcam info: error: "):]
        internal = [ln for ln in lines if ln.startswith("simcam info: internal error: ")]
        if res.get("outcome") == "other" and internal:
            msg = internal[-1][len("simcam info: internal error: "):]
            res["type"], _, res["message"] = msg.partition(": ")
            stray = [ln for ln in stray if ln not in internal]
    else:
        stray = lines
    stray += res.get("warnings", [])
    if res.get("outcome") == "simcam_error" and str(task.path) not in res.get("message", ""):
        res["outcome"] = "unnamed"
    if stray and res.get("outcome") in ("ok", "simcam_error"):
        res["outcome"] = "stray"
        res["message"] = stray[0][:300]
    res["stray"] = stray[:3]
    res["peak_mib"] = max(0.0, (rusage.ru_maxrss - base_rss_kb) / 1024.0) if rusage is not None else 0.0
    res["wall"] = time.monotonic() - task.start
    res["cpu"] = cpu
    return res


def _address_space() -> int:
    """This process's virtual size in bytes (``VmSize``; 0 where /proc is missing).

    A child inherits it, so RLIMIT_AS is set to it plus ``--mem-gb``: a mutant may allocate that much
    whatever the parent holds (the harness about 0.3 GiB; a test process with torch loaded, several).
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


class Runner:
    """At most ``workers`` forked children at a time, each with RLIMIT_AS and a time limit.

    The limit is on CPU time (RLIMIT_CPU, ``timeout`` seconds rounded up): the machine may be shared,
    so wall time measures the neighbours too. A child still running after 3 x ``timeout`` wall-clock
    seconds (asleep, or starved) is killed and counted as a time-out as well.
    """

    def __init__(self, workdir: Path, workers: int, timeout: float, mem_gb: float):
        self.workdir, self.workers, self.timeout = workdir, max(1, workers), timeout
        self.cpu_limit = max(1, math.ceil(timeout))
        self.mem_bytes = _address_space() + int(mem_gb * (1 << 30))
        self.running: dict[int, Task] = {}
        self.base_rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    def start(self, task: Task) -> None:
        for p in (task.res_path, task.err_path):
            p.unlink(missing_ok=True)
        sys.stdout.flush()
        sys.stderr.flush()
        task.cpu_limit = self.cpu_limit
        pid = os.fork()
        if pid == 0:
            _child_main(task.target, task.path, task.res_path, task.err_path, self.mem_bytes, self.cpu_limit)
        task.pid, task.start = pid, time.monotonic()
        self.running[pid] = task

    def reap(self, block: bool = True) -> list[tuple[Task, dict]]:
        """Finished children (killing those over time); waits for at least one when ``block``."""
        done = []
        while True:
            for pid in list(self.running):  # our children only (never another child of this process)
                wpid, status, rusage = os.wait4(pid, os.WNOHANG)
                if wpid:
                    task = self.running.pop(pid)
                    done.append((task, _classify(task, status, rusage, self.base_rss_kb)))
            now = time.monotonic()
            for task in self.running.values():
                if not task.timed_out and now - task.start > 3 * self.timeout:
                    task.timed_out = True
                    os.kill(task.pid, signal.SIGKILL)
            if done or not block or not self.running:
                return done
            time.sleep(0.002)

    def run_one(self, target: str, path: Path) -> dict:
        """Run one target now (used by the minimiser)."""
        task = Task(-1, target, path, self.workdir / "min.json", self.workdir / "min.err")
        self.start(task)
        while True:
            for t, res in self.reap():
                if t is task:
                    return res


# ---------------------------------------------------------------------------------------------
# the campaign
# ---------------------------------------------------------------------------------------------
def signature(target: str, res: dict) -> tuple:
    """What makes two bugs the same: target, outcome, exception type and where (or the stray text)."""
    if res["outcome"] in ("stray", "unnamed"):
        text = "".join(c for c in res.get("message", "") if not c.isdigit())
        return target, res["outcome"], text.split(":")[0][-60:] if res["outcome"] == "unnamed" else text[:60]
    return target, res["outcome"], res.get("type", ""), res.get("where", "")


def minimise(runner: Runner, seed: bytes, edits: list[dict], target: str, sig: tuple, path: Path) -> list[dict]:
    """Drop edits one at a time while the same bug (:func:`signature`) still happens."""
    edits = list(edits)
    k = 0
    while k < len(edits) and len(edits) > 1:
        trial = edits[:k] + edits[k + 1:]
        path.write_bytes(build_mutant(seed, trial))
        if signature(target, runner.run_one(target, path)) == sig:
            edits = trial
        else:
            k += 1
    return edits


@dataclass
class Stats:
    counts: dict[str, dict[str, int]] = field(default_factory=lambda: {t: {} for t in TARGETS})
    slowest: dict[str, float] = field(default_factory=lambda: {t: 0.0 for t in TARGETS})
    slowest_wall: dict[str, float] = field(default_factory=lambda: {t: 0.0 for t in TARGETS})
    peak: dict[str, float] = field(default_factory=lambda: {t: 0.0 for t in TARGETS})
    #: SimcamErrors that wrap a library exception (a tag the reader did not check itself): not bugs,
    #: but where validation could name the tag better. Message prefix -> (count, example).
    wrapped: dict[str, list] = field(default_factory=dict)

    def add(self, target: str, res: dict) -> None:
        c = self.counts[target]
        c[res["outcome"]] = c.get(res["outcome"], 0) + 1
        msg = res.get("message", "")
        if res["outcome"] == "simcam_error" and re.search(r"\((\w+Error|\w+Exception): ", msg):
            key = re.sub(r"^.*?\.dng: ", "", msg)[:60]
            entry = self.wrapped.setdefault(key, [0, msg])
            entry[0] += 1
        self.slowest[target] = max(self.slowest[target], float(res.get("cpu", 0.0)))
        self.slowest_wall[target] = max(self.slowest_wall[target], float(res.get("wall", 0.0)))
        self.peak[target] = max(self.peak[target], float(res.get("peak_mib", 0.0)))

    def table(self, mutants: int) -> str:
        head = ["target", "runs"] + [name for _, name in COLUMNS] + ["max CPU s", "max wall s", "peak MiB"]
        rows = []
        total = {k: 0 for k, _ in COLUMNS}
        for t in TARGETS:
            c = self.counts[t]
            rows.append([t, str(sum(c.values()))] + [str(c.get(k, 0)) for k, _ in COLUMNS]
                        + [f"{self.slowest[t]:.2f}", f"{self.slowest_wall[t]:.2f}", f"{self.peak[t]:.0f}"])
            for k, _ in COLUMNS:
                total[k] += c.get(k, 0)
        rows.append(["total", str(sum(total.values()))] + [str(total[k]) for k, _ in COLUMNS]
                    + [f"{max(self.slowest.values()):.2f}", f"{max(self.slowest_wall.values()):.2f}",
                       f"{max(self.peak.values()):.0f}"])
        widths = [max(len(r[i]) for r in [head] + rows) for i in range(len(head))]
        fmt = "  ".join("{:<%d}" % widths[0] if i == 0 else "{:>%d}" % w for i, w in enumerate(widths))
        lines = [f"{mutants} mutants x {len(TARGETS)} targets", fmt.format(*head)]
        lines += [fmt.format(*r) for r in rows]
        return "\n".join(lines)

    def bugs(self) -> int:
        return sum(c.get(k, 0) for c in self.counts.values() for k in BUG_OUTCOMES)


def _edited_tags(edits: list[dict]) -> list[str]:
    tags = []
    for e in edits:
        if "tag" in e:
            tags.append(tag_name(tag_code(e["tag"])))
        elif "list" in e:
            tags.append(f"OpcodeList{e['list']}")
    return tags


def _save_bug(out: Path, k: int, seed_name: str, edits: list[dict], target: str, res: dict, data: bytes,
              corpus: Path | None) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"bug-{k:03d}-{target}-{res['outcome']}"
    recipe = {"seed": seed_name, "edits": edits, "target": target, "outcome": res["outcome"],
              "type": res.get("type", ""), "message": res.get("message", ""), "where": res.get("where", "")}
    stem.with_suffix(".json").write_text(json.dumps(recipe, indent=1) + "\n")
    stem.with_suffix(".dng").write_bytes(data)
    if corpus is not None and seed_name in WRITTEN_SEEDS:
        corpus.mkdir(parents=True, exist_ok=True)
        digest = hashlib.sha256(json.dumps([seed_name, edits], sort_keys=True).encode()).hexdigest()[:10]
        case = {"name": f"found-{digest}", "cause": f"{target}: {res.get('type') or res['outcome']}: "
                f"{res.get('message', '')[:120]}", "seed": seed_name, "edits": edits, "tags": _edited_tags(edits)}
        (corpus / f"found-{digest}.json").write_text(json.dumps(case, indent=1) + "\n")
    return stem.with_suffix(".dng")


def _warm_up(workdir: Path) -> None:
    """Import and run everything once before forking (children then start warm and cheap)."""
    import warnings

    import simcam
    import simcam.cli  # noqa: F401

    for name in ("plain", "opcodes", "levels"):
        data = seed_bytes(name, workdir)
        path = workdir / f"warm-{name}.dng"
        path.write_bytes(data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the opcodes seed's optional FixVignetteRadial
            simcam.read(path)
            simcam.render(path)


def fuzz(mutants: int, seed: int, timeout: float, mem_gb: float, workers: int, out: Path,
         corpus: Path | None, seeds: list[str] | None = None, verbose: bool = True) -> Stats:
    """Run the campaign; returns the statistics (the table, the bug count)."""
    base = Path("/dev/shm") if Path("/dev/shm").is_dir() and os.access("/dev/shm", os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="simcam-fuzz-", dir=base) as tmp:
        workdir = Path(tmp)
        _warm_up(workdir)
        names = seeds or available_seeds()
        blobs = {n: seed_bytes(n, workdir) for n in names}
        # simcam-written seeds are small and fast: they get most mutants; each shared seed a few
        weights = [1.0 if n in WRITTEN_SEEDS or n == "chart" else 0.35 for n in names]
        rng = random.Random(seed)
        runner = Runner(workdir, workers, timeout, mem_gb)
        stats = Stats()
        bugs: dict[tuple, tuple] = {}
        pending: list[Task] = []
        info: dict[int, tuple[str, list[dict]]] = {}
        remaining: dict[int, int] = {}
        made = 0
        t0 = time.monotonic()
        while made < mutants or pending or runner.running:
            while len(pending) < 2 * runner.workers and made < mutants:
                name = rng.choices(names, weights)[0]
                edits = make_edits(rng, blobs[name])
                path = workdir / f"m{made}.dng"
                path.write_bytes(build_mutant(blobs[name], edits))
                info[made], remaining[made] = (name, edits), len(TARGETS)
                pending += [Task(made, t, path, workdir / f"r{made}-{t}.json", workdir / f"r{made}-{t}.err")
                            for t in TARGETS]
                made += 1
                if verbose and made % 500 == 0:
                    print(f"  {made} mutants started, {time.monotonic() - t0:.0f} s, distinct bugs so far: "
                          f"{len(bugs)}", flush=True)
            while pending and len(runner.running) < runner.workers:
                runner.start(pending.pop(0))
            for task, res in runner.reap():
                stats.add(task.target, res)
                if res["outcome"] in BUG_OUTCOMES:
                    sig = signature(task.target, res)
                    if sig not in bugs:
                        bugs[sig] = (task.mutant, task.target, res, *info[task.mutant])
                        if verbose:
                            print(f"  new bug: {task.target} {res['outcome']} {res.get('type', '')} "
                                  f"{res.get('message', '')[:160]} [{info[task.mutant][0]}]", flush=True)
                remaining[task.mutant] -= 1
                if remaining[task.mutant] == 0:
                    task.path.unlink(missing_ok=True)
                    info.pop(task.mutant)
                for p in (task.res_path, task.err_path):
                    p.unlink(missing_ok=True)
        for k, (sig, (_, target, res, name, edits)) in enumerate(sorted(bugs.items(), key=lambda kv: str(kv[0]))):
            path = workdir / "minimise.dng"
            small = minimise(runner, blobs[name], edits, target, sig, path)
            data = build_mutant(blobs[name], small)
            saved = _save_bug(out, k, name, small, target, res, data, corpus)
            print(f"BUG {target} {res['outcome']} {res.get('type', '')}: {res.get('message', '')[:200]} "
                  f"({res.get('where', '')}; seed {name}; {len(small)} edit(s); {saved})")
    return stats


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mutants", type=int, default=1000, help="number of mutants (each runs 3 targets)")
    ap.add_argument("--seed", type=int, default=0, help="random seed of the mutations")
    ap.add_argument("--timeout", type=float, default=5.0,
                    help="CPU seconds per target run (RLIMIT_CPU; 3x that in wall time at most)")
    ap.add_argument("--mem-gb", type=float, default=2.0,
                    help="GiB a target run may allocate (RLIMIT_AS: the forked worker's size plus this)")
    ap.add_argument("--workers", type=int, default=2, help="children at a time")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "fuzz", help="where bugs are saved")
    ap.add_argument("--corpus", type=Path, default=None,
                    help=f"also write recipes of bugs on simcam-written seeds here (e.g. {CORPUS_DIR.relative_to(ROOT)})")
    ap.add_argument("--seeds", nargs="*", default=None, help=f"seed names (default: all of {available_seeds()})")
    args = ap.parse_args(argv)
    t0 = time.monotonic()
    stats = fuzz(args.mutants, args.seed, args.timeout, args.mem_gb, args.workers, args.out, args.corpus, args.seeds)
    print(stats.table(args.mutants))
    if stats.wrapped:
        print(f"SimcamErrors wrapping a library exception (not bugs): {sum(n for n, _ in stats.wrapped.values())}")
        for n, example in sorted(stats.wrapped.values(), key=lambda e: -e[0])[:10]:
            print(f"  {n:5d}  {example[:200]}")
    print(f"{time.monotonic() - t0:.0f} s; {stats.bugs()} run(s) with a bug")
    return 1 if stats.bugs() else 0


if __name__ == "__main__":
    sys.exit(main())
