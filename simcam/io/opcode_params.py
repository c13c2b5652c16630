"""Parameters of the DNG opcodes simcam applies besides GainMap (Adobe DNG Specification 1.7, ch. 7).

Every payload is big-endian. Most opcodes start with an *area spec*: ``Top, Left, Bottom,
Right`` (int32; an empty rectangle means the whole image), ``Plane, Planes, RowPitch,
ColPitch`` (uint32) — the pixels ``rows Top, Top + RowPitch, ... < Bottom`` and likewise
columns, in planes ``Plane .. Plane + Planes - 1``.

Opcodes (id): WarpRectilinear (1), FixBadPixelsConstant (4), FixBadPixelsList (5),
TrimBounds (6), MapTable (7), MapPolynomial (8), DeltaPerRow (10), DeltaPerColumn (11),
ScalePerRow (12), ScalePerColumn (13). Others are named by :data:`OPCODE_NAMES` and left to the
caller (a warning, or an error when their Optional flag is clear).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from ..errors import DngError
from ..frame import AreaSpec

OPCODE_NAMES = {1: "WarpRectilinear", 2: "WarpFisheye", 3: "FixVignetteRadial", 4: "FixBadPixelsConstant",
                5: "FixBadPixelsList", 6: "TrimBounds", 7: "MapTable", 8: "MapPolynomial", 9: "GainMap",
                10: "DeltaPerRow", 11: "DeltaPerColumn", 12: "ScalePerRow", 13: "ScalePerColumn",
                14: "WarpRectilinear2"}
#: Flag bits of an opcode (DNG 1.7 sec. 7.1): the opcode may be skipped / skipped for previews.
FLAG_OPTIONAL, FLAG_PREVIEW_SKIP = 1, 2
_AREA = struct.Struct(">4i4I")
#: Largest table or list simcam decodes (entries); real files hold a few thousand.
MAX_ENTRIES = 1 << 24


@dataclass(frozen=True)
class WarpRectilinear:
    """Radial + tangential lens-distortion correction (id 1), per plane: kr0..kr3, kt0, kt1; optical centre."""

    coefficients: np.ndarray  # (planes, 6): kr0, kr1, kr2, kr3, kt0, kt1
    center: tuple[float, float]  # (cx, cy), relative to the image (0..1)


@dataclass(frozen=True)
class FixBadPixelsConstant:
    """Pixels holding ``constant`` are bad (id 4); ``bayer_phase`` gives the CFA phase (0: top-left red)."""

    constant: int
    bayer_phase: int


@dataclass(frozen=True)
class FixBadPixelsList:
    """Listed bad points (row, col) and rectangles (t, l, b, r) (id 5)."""

    bayer_phase: int
    points: np.ndarray  # (n, 2) int
    rects: np.ndarray  # (m, 4) int


@dataclass(frozen=True)
class TrimBounds:
    """Crop the image to (top, left, bottom, right) (id 6)."""

    top: int
    left: int
    bottom: int
    right: int


@dataclass(frozen=True)
class MapTable:
    """Replace each value v (16-bit code) by ``table[min(v, n - 1)]`` (id 7)."""

    area: AreaSpec
    table: np.ndarray  # uint16


@dataclass(frozen=True)
class MapPolynomial:
    """Replace each value x (0..1) by ``sum c_k x^k`` (id 8)."""

    area: AreaSpec
    coefficients: np.ndarray  # float64, degree + 1


@dataclass(frozen=True)
class PerLine:
    """DeltaPerRow/Column (x + d, ids 10/11) or ScalePerRow/Column (x * s, ids 12/13)."""

    area: AreaSpec
    axis: str  # "row" | "column"
    op: str  # "delta" | "scale"
    values: np.ndarray  # float32, one per selected row / column


def _read(fmt: str, payload: bytes, offset: int, where: str):
    st = struct.Struct(fmt)
    if offset + st.size > len(payload):
        raise DngError(f"{where}: payload of {len(payload)} bytes ends inside its parameters (needs "
                       f"{offset + st.size}); expected a complete opcode")
    return st.unpack_from(payload, offset), offset + st.size


def _area(payload: bytes, offset: int, where: str) -> tuple[AreaSpec, int]:
    v, offset = _read(_AREA.format, payload, offset, where)
    a = AreaSpec(*v)
    if a.planes < 1 or a.row_pitch < 1 or a.col_pitch < 1:
        raise DngError(f"{where}: area Planes/RowPitch/ColPitch = {a.planes}/{a.row_pitch}/{a.col_pitch}; "
                       "expected >= 1")
    return a, offset


def _count(n: int, where: str, what: str) -> int:
    if n > MAX_ENTRIES:
        raise DngError(f"{where}: {what} of {n} entries; expected at most {MAX_ENTRIES}")
    return n


def _finite(values: np.ndarray, where: str, what: str) -> np.ndarray:
    if not np.isfinite(values).all():
        raise DngError(f"{where}: {what}: non-finite value; expected finite numbers")
    return values


def decode_opcode(op_id: int, payload: bytes, *, where: str):
    """Decode the parameters of opcode ``op_id`` (None for opcodes without a decoder here).

    Raises
    ------
    DngError
        A payload shorter or longer than its parameters, absurd counts, non-finite values.
    """
    p = bytes(payload)
    name = OPCODE_NAMES.get(op_id, f"opcode {op_id}")
    where = f"{where} ({name})"
    if op_id == 1:
        (planes,), o = _read(">I", p, 0, where)
        if not 1 <= planes <= 4:
            raise DngError(f"{where}: {planes} planes; expected 1 to 4")
        need = 4 + planes * 48 + 16
        if len(p) != need:
            raise DngError(f"{where}: {len(p)} bytes for {planes} planes; expected {need}")
        coef = _finite(np.frombuffer(p, ">f8", planes * 6, o).reshape(planes, 6).astype(np.float64), where,
                       "coefficients")
        cx, cy = _finite(np.frombuffer(p, ">f8", 2, o + planes * 48).astype(np.float64), where, "center")
        if not (0 <= cx <= 1 and 0 <= cy <= 1):
            raise DngError(f"{where}: center ({cx}, {cy}); expected relative coordinates in [0, 1]")
        return WarpRectilinear(coef, (float(cx), float(cy)))
    if op_id == 4:
        (const, phase), o = _read(">2I", p, 0, where)
        return FixBadPixelsConstant(int(const), int(phase) % 4)
    if op_id == 5:
        (phase, n_pts, n_rects), o = _read(">3I", p, 0, where)
        _count(n_pts + n_rects, where, "bad-pixel list")
        need = 12 + 8 * n_pts + 16 * n_rects
        if len(p) != need:
            raise DngError(f"{where}: {len(p)} bytes for {n_pts} points and {n_rects} rectangles; expected {need}")
        pts = np.frombuffer(p, ">u4", 2 * n_pts, 12).reshape(n_pts, 2).astype(np.int64)
        rects = np.frombuffer(p, ">u4", 4 * n_rects, 12 + 8 * n_pts).reshape(n_rects, 4).astype(np.int64)
        return FixBadPixelsList(int(phase) % 4, pts, rects)
    if op_id == 6:
        (t, l, b, r), o = _read(">4i", p, 0, where)
        if b <= t or r <= l:
            raise DngError(f"{where}: bounds ({t}, {l}, {b}, {r}); expected a non-empty rectangle")
        return TrimBounds(t, l, b, r)
    if op_id == 7:
        area, o = _area(p, 0, where)
        (n,), o = _read(">I", p, o, where)
        if not 1 <= _count(n, where, "table") <= 65536:
            raise DngError(f"{where}: table of {n} entries; expected 1 to 65536")
        if len(p) != o + 2 * n:
            raise DngError(f"{where}: {len(p)} bytes for a table of {n}; expected {o + 2 * n}")
        return MapTable(area, np.frombuffer(p, ">u2", n, o).astype(np.uint16))
    if op_id == 8:
        area, o = _area(p, 0, where)
        (degree,), o = _read(">I", p, o, where)
        if degree > 8:
            raise DngError(f"{where}: degree {degree}; expected at most 8")
        if len(p) != o + 8 * (degree + 1):
            raise DngError(f"{where}: {len(p)} bytes for degree {degree}; expected {o + 8 * (degree + 1)}")
        return MapPolynomial(area, _finite(np.frombuffer(p, ">f8", degree + 1, o).astype(np.float64), where,
                                           "coefficients"))
    if op_id in (10, 11, 12, 13):
        area, o = _area(p, 0, where)
        (n,), o = _read(">I", p, o, where)
        _count(n, where, "table")
        if len(p) != o + 4 * n:
            raise DngError(f"{where}: {len(p)} bytes for {n} values; expected {o + 4 * n}")
        values = _finite(np.frombuffer(p, ">f4", n, o).astype(np.float32), where, "values")
        axis = "row" if op_id in (10, 12) else "column"
        return PerLine(area, axis, "delta" if op_id in (10, 11) else "scale", values)
    return None
