"""``opcodes``: apply a DNG opcode list where the DNG SDK applies it (Adobe DNG Specification 1.7, ch. 7).

* ``list: 1`` — OpcodeList1, on the stored raw values (DN) before linearisation: put it first;
  its coordinates are those of the whole stored image.
* ``list: 2`` — OpcodeList2, on the linearised, black-subtracted, normalised mosaic of the
  active area (after ``normalize`` and ``crop: active_area``). Its GainMaps are left to
  ``lens_shading`` unless ``gain_maps: true``.
* ``list: 3`` — OpcodeList3, on the demosaicked camera RGB of the active area (before the
  default crop): WarpRectilinear (lens distortion), GainMaps per plane, ...

Applied: WarpRectilinear, FixBadPixelsConstant, FixBadPixelsList, TrimBounds, MapTable,
MapPolynomial, DeltaPerRow/Column, ScalePerRow/Column and GainMap. An opcode simcam cannot apply
is a :class:`~simcam.errors.SimcamWarning` naming it when its Optional flag is set, a
:class:`~simcam.errors.StageError` when it is not (DNG 1.7 sec. 7.1: a reader must not
ignore a non-optional opcode).

Value domains follow the SDK: list 1 works on 16-bit codes (values / 65535 for the
polynomial, delta and scale opcodes), lists 2 and 3 on values in [0, 1]; MapTable looks up
``round(x * 65535)`` there. Delta results are clipped to [-1, 1], scale results to [0, 1],
as in ``dng_misc_opcodes.cpp``.
"""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np

from ..cfa import shift_pattern
from ..errors import SimcamWarning, StageError
from ..frame import MOSAIC_KINDS, RawFrame
from ..io.opcode_params import (FLAG_OPTIONAL, OPCODE_NAMES, FixBadPixelsConstant, FixBadPixelsList, MapPolynomial,
                                MapTable, PerLine, TrimBounds, WarpRectilinear, decode_opcode)
from .base import Stage, StageParams, register_stage

_KIND = {1: "raw_dn", 2: "raw", 3: "camera_rgb"}
_CODE = 65535.0
#: Rows per band of :func:`warp_rectilinear` (its coordinate arrays stay in the cache).
_WARP_BAND = 128


def _planes(data: np.ndarray) -> np.ndarray:
    """(H, W, P) view of a mosaic (P = 1) or an RGB image."""
    return data[:, :, None] if data.ndim == 2 else data


def fill_bad_pixels(data: np.ndarray, bad: np.ndarray, *, green_parity: int | None) -> np.ndarray:
    """Replace ``bad`` mosaic pixels by the mean of their good same-colour neighbours.

    Same colour: the 4 pixels 2 away along rows and columns; a green site (``(y + x) % 2 ==
    green_parity``) also uses its 4 diagonal neighbours. A pixel without a good neighbour keeps
    its value. ``green_parity`` None: a monochrome image (the 8 adjacent pixels).
    """
    out = data.astype(np.float64, copy=True)
    h, w = data.shape
    good = ~bad
    ys, xs = np.nonzero(bad)
    if ys.size == 0:
        return data
    axial = [(-2, 0), (2, 0), (0, -2), (0, 2)]
    diag = [(-1, -1), (-1, 1), (1, -1), (1, 1)]
    total = np.zeros(ys.size)
    count = np.zeros(ys.size)
    is_green = np.zeros(ys.size, bool) if green_parity is None else ((ys + xs) % 2 == green_parity)
    offsets = [(o, None) for o in axial] + [(o, "green") for o in diag]
    if green_parity is None:
        offsets = [((dy, dx), None) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]
    for (dy, dx), only in offsets:
        yy, xx = ys + dy, xs + dx
        ok = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
        if only == "green":
            ok &= is_green
        yy, xx = np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)
        ok &= good[yy, xx]
        total += np.where(ok, data[yy, xx], 0.0)
        count += ok
    have = count > 0
    out[ys[have], xs[have]] = total[have] / count[have]
    return out.astype(data.dtype)


def _green_parity(bayer_phase: int) -> int:
    """Parity of (y + x) at the green sites for DNG BayerPhase 0 (R), 1 (G), 2 (G), 3 (B) at (0, 0)."""
    return 0 if bayer_phase in (1, 2) else 1


def _clamped(pos: np.ndarray, last: int, centre: float) -> np.ndarray:
    """Source positions clamped to ``0 .. last`` (an overflow to +-inf clamps too; NaN takes the centre)."""
    return np.clip(np.nan_to_num(pos, nan=centre, posinf=last, neginf=0.0), 0, last)


def warp_rectilinear(rgb: np.ndarray, op: WarpRectilinear, *, order: int = 1) -> np.ndarray:
    """Undistort an (H, W, P) image as the DNG SDK's ``dng_filter_warp`` does (square pixels).

    For destination pixel d, with c the optical centre (``l + cx (r - l)``, ``t + cy (b - t)``)
    and R the largest distance from c to a corner of the image, ``u = (d - c) / R``,
    ``r^2 = min(|u|^2, 1)``; the source position is ``c + R (u (kr0 + kr1 r^2 + kr2 r^4 + kr3 r^6)
    + t(u))`` with the tangential term ``t_v = kt0 (r^2 + 2 u_v^2) + 2 kt1 u_h u_v``, ``t_h = kt1
    (r^2 + 2 u_h^2) + 2 kt0 u_h u_v``; the source is clamped to the image and resampled.
    """
    from scipy.ndimage import map_coordinates

    img = _planes(rgb)
    h, w, n = img.shape
    cx, cy = op.center
    c_v, c_h = cy * h, cx * w
    corners = np.array([[0, 0], [0, w], [h, 0], [h, w]], np.float64)
    radius = float(np.sqrt(((corners - [c_v, c_h]) ** 2).sum(1)).max())
    uh = (np.arange(w, dtype=np.float64) - c_h) / radius
    planes = [np.ascontiguousarray(img[:, :, p], dtype=np.float32) for p in range(n)]
    out = np.empty_like(img, dtype=np.float32)
    for r0 in range(0, h, _WARP_BAND):  # row bands: the same numbers, a fraction of the memory
        r1 = min(h, r0 + _WARP_BAND)
        uv = ((np.arange(r0, r1, dtype=np.float64) - c_v) / radius)[:, None]
        r2 = np.minimum(uv * uv + uh * uh, 1.0)
        for p in range(n):
            kr0, kr1, kr2, kr3, kt0, kt1 = op.coefficients[min(p, op.coefficients.shape[0] - 1)]
            with np.errstate(over="ignore", invalid="ignore"):  # absurd (finite) coefficients: clamped below
                ratio = kr0 + r2 * (kr1 + r2 * (kr2 + r2 * kr3))
                tv = kt0 * (r2 + 2 * uv * uv) + 2 * kt1 * uh * uv
                th = kt1 * (r2 + 2 * uh * uh) + 2 * kt0 * uh * uv
                sv = _clamped(c_v + radius * (uv * ratio + tv), h - 1, c_v)
                sh = _clamped(c_h + radius * (uh * ratio + th), w - 1, c_h)
            out[r0:r1, :, p] = map_coordinates(planes[p], [sv, sh], order=order, mode="nearest")
    return out[:, :, 0] if rgb.ndim == 2 else out


@register_stage
class Opcodes(Stage, type="opcodes", accepts=frozenset(_KIND.values())):
    """Apply OpcodeList1, 2 or 3 (module docstring)."""

    class Params(StageParams):
        list: Literal[1, 2, 3] = 3
        #: apply GainMaps here too (list 2: normally lens_shading's job)
        gain_maps: bool = False
        #: WarpRectilinear resampling: 1 bilinear, 3 cubic spline
        interpolation: Literal[1, 3] = 1

    def passes_through(self, frame: RawFrame) -> bool:
        return not getattr(frame.meta, f"opcode_list{int(self.params.list)}")

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        n = int(self.params.list)
        meta = frame.meta
        ops = list(getattr(meta, f"opcode_list{n}") or [])
        if not ops:
            return frame.evolve(step=f"{self.type}{n}(none)")
        src = meta.source or "frame"
        if frame.kind != _KIND[n]:
            raise StageError(f"{src}: opcodes list {n}: applies to {_KIND[n]!r} frames, got {frame.kind!r}; "
                             "place it where the DNG SDK applies it (see the stage's documentation)")
        data = np.array(frame.data, dtype=np.float32, copy=True)
        meta = meta.copy()
        geometry = None  # where the GainMaps sit: computed once, a list may hold thousands of them
        for k, op in enumerate(ops):
            name = OPCODE_NAMES.get(op.id, f"id {op.id}")
            where = f"{src}: OpcodeList{n}[{k}]"
            if op.id == 9:
                if n != 2 or self.params.gain_maps:
                    if geometry is None or geometry[2] != data.shape[:2]:
                        geometry = self._gain_map_geometry(frame, data.shape[:2], n)
                    data = self._gain_map(data, op, geometry)
                continue
            params = decode_opcode(op.id, op.payload, where=where)
            if params is None:
                self._unsupported(where, name, op)
                continue
            data, meta = self._apply_one(data, meta, frame.kind, params, n, where)
        return frame.evolve(data, meta=meta, step=f"{self.type}{n}")

    @staticmethod
    def _unsupported(where: str, name: str, op) -> None:
        if op.flags & FLAG_OPTIONAL:
            warnings.warn(SimcamWarning(f"{where}: {name} (optional) is not applied by simcam"), stacklevel=2)
            return
        raise StageError(f"{where}: {name} (id {op.id}) cannot be applied by simcam and its Optional flag is clear; "
                         "expected an opcode simcam implements (a reader must not skip a non-optional opcode)")

    @staticmethod
    def _gain_map_geometry(frame: RawFrame, shape: tuple[int, int], n: int):
        """(metadata, opcode-image bounds, shape) placing the GainMaps of list ``n`` on a ``shape`` image."""
        from .lens_shading import opcode_image_bounds

        meta = frame.meta
        if n == 1:  # OpcodeList1 addresses the whole stored image
            extra = dict(meta.extra) if isinstance(meta.extra, dict) else {}
            extra["image_size"] = tuple(shape)
            meta = meta.replace(active_area=None, extra=extra, origin=(0, 0))
        return meta, opcode_image_bounds(meta, shape), tuple(shape)

    @staticmethod
    def _gain_map(data: np.ndarray, op, geometry) -> np.ndarray:
        from .lens_shading import gain_map_patch

        gm = op.parsed
        meta, bounds, shape = geometry
        img = _planes(data)
        patch = gain_map_patch(gm, meta, shape, bounds)
        if patch is not None:
            rs, cs, gain = patch
            gain = np.float64(gain) if np.isscalar(gain) else gain  # float64 product, as for a map of many points
            for p in range(int(gm.plane), min(int(gm.plane) + max(int(gm.planes), 1), img.shape[2])):
                img[rs, cs, p] = (img[rs, cs, p] * gain).astype(np.float32)
        return data

    def _apply_one(self, data, meta, kind, op, n: int, where: str):
        scale = _CODE if n == 1 else 1.0  # list 1 holds 16-bit codes
        if isinstance(op, WarpRectilinear):
            if data.ndim != 3:
                raise StageError(f"{where}: WarpRectilinear applies to demosaicked RGB (OpcodeList3); got a mosaic")
            return warp_rectilinear(data, op, order=int(self.params.interpolation)), meta
        if isinstance(op, (FixBadPixelsConstant, FixBadPixelsList)):
            if data.ndim != 2:
                raise StageError(f"{where}: bad-pixel opcodes apply to the mosaic (OpcodeList1/2)")
            if isinstance(op, FixBadPixelsConstant):
                bad = data == np.float32(op.constant if n == 1 else op.constant / _CODE)
            else:
                bad = np.zeros(data.shape, bool)
                pts = op.points[(op.points[:, 0] < data.shape[0]) & (op.points[:, 1] < data.shape[1])]
                bad[pts[:, 0], pts[:, 1]] = True
                for t, l, b, r in op.rects:
                    bad[t:b, l:r] = True
            parity = None if meta.cfa is None else _green_parity(op.bayer_phase)
            return fill_bad_pixels(data, bad, green_parity=parity), meta
        if isinstance(op, TrimBounds):
            t, l, b, r = max(op.top, 0), max(op.left, 0), min(op.bottom, data.shape[0]), min(op.right, data.shape[1])
            if not (t < b and l < r):
                raise StageError(f"{where}: TrimBounds ({op.top}, {op.left}, {op.bottom}, {op.right}) outside the "
                                 f"{data.shape[0]}x{data.shape[1]} image")
            if kind in MOSAIC_KINDS and meta.cfa is not None and (t % 2 or l % 2):
                meta.cfa = shift_pattern(meta.cfa, t, l)
            meta.origin = (meta.origin[0] + t, meta.origin[1] + l)
            return np.ascontiguousarray(data[t:b, l:r]), meta
        img = _planes(data)
        rs, cs = op.area.slices(img.shape[:2])
        for p in op.area.plane_range(img.shape[2]):
            v = img[rs, cs, p]
            if isinstance(op, MapTable):
                code = np.clip(np.rint(v if n == 1 else v * _CODE), 0, op.table.size - 1).astype(np.int64)
                new = op.table[code].astype(np.float64) / (1.0 if n == 1 else _CODE)
            elif isinstance(op, MapPolynomial):
                x = v.astype(np.float64) / scale
                new = np.polynomial.polynomial.polyval(x, op.coefficients) * scale
            elif isinstance(op, PerLine):
                sl, origin, pitch = (rs, op.area.top, op.area.row_pitch) if op.axis == "row" else \
                    (cs, op.area.left, op.area.col_pitch)
                empty = op.area.bottom <= op.area.top or op.area.right <= op.area.left
                start = 0 if empty else (sl.start - origin) // pitch
                lines = v.shape[0] if op.axis == "row" else v.shape[1]
                if start + lines > op.values.size:
                    raise StageError(f"{where}: {op.values.size} {op.axis} values for {start + lines} {op.axis}s; "
                                     "expected one per selected line")
                vals = op.values[start:start + lines].astype(np.float64)
                vals = vals[:, None] if op.axis == "row" else vals[None, :]
                x = v.astype(np.float64) / scale
                new = (np.clip(x + vals, -1.0, 1.0) if op.op == "delta" else np.clip(x * vals, 0.0, 1.0)) * scale
            else:  # pragma: no cover - decode_opcode returns only the classes above
                raise StageError(f"{where}: unhandled opcode {type(op).__name__}")
            img[rs, cs, p] = new.astype(np.float32)
        return data, meta
