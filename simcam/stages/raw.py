"""Raw-domain stages: ``normalize`` and ``crop``.

``normalize`` maps sensor DN to normalised raw (DNG spec chapter 5, "Mapping
Raw Values to Linear Reference Values"): linearization table, then black level
per CFA site (BlackLevel with BlackLevelRepeatDim, plus BlackLevelDeltaH/V),
then division by (white - black). Negatives are kept.
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np

from ..cfa import shift_pattern
from ..errors import MetadataError, StageError
from ..frame import MOSAIC_KINDS, SIGNAL_KINDS, RawFrame
from .base import Stage, StageParams, register_stage


def black_level_map(meta, shape: tuple[int, int]) -> np.ndarray:
    """Per-pixel black level (DN, float32) of an H x W frame at ``meta.origin``.

    The BlackLevel pattern and the delta tags are anchored at the top-left of
    the ActiveArea (DNG 1.6, BlackLevel); pixels outside the active area use
    the pattern without deltas.
    """
    h, w = shape
    top, left = (meta.active_area[0], meta.active_area[1]) if meta.active_area else (0, 0)
    rows = np.arange(h) + meta.origin[0] - top
    cols = np.arange(w) + meta.origin[1] - left
    bl = np.asarray(meta.black_level, dtype=np.float64)
    if bl.ndim == 0:
        bl = bl.reshape(1, 1)
    if bl.ndim == 3:  # (rows, cols, samples) with one sample
        bl = bl[..., 0]
    r, c = bl.shape
    black = bl[np.ix_(rows % r, cols % c)]
    if meta.black_level_delta_v is not None:
        dv = np.asarray(meta.black_level_delta_v, dtype=np.float64)
        ok = (rows >= 0) & (rows < dv.size)
        black = black + np.where(ok, dv[np.clip(rows, 0, dv.size - 1)], 0.0)[:, None]
    if meta.black_level_delta_h is not None:
        dh = np.asarray(meta.black_level_delta_h, dtype=np.float64)
        ok = (cols >= 0) & (cols < dh.size)
        black = black + np.where(ok, dh[np.clip(cols, 0, dh.size - 1)], 0.0)[None, :]
    return black.astype(np.float32)


def black_level_cell(meta, shape: tuple[int, int]) -> np.ndarray | None:
    """The BlackLevel repeat pattern (DN, float32) re-phased to start at ``data[0, 0]``.

    Equals one cell of :func:`black_level_map` when no BlackLevelDeltaH/V apply
    and the frame is a whole number of cells; returns None otherwise.
    """
    if meta.black_level_delta_v is not None or meta.black_level_delta_h is not None:
        return None
    bl = np.asarray(meta.black_level, dtype=np.float64)
    if bl.ndim == 0:
        bl = bl.reshape(1, 1)
    if bl.ndim == 3:
        bl = bl[..., 0]
    r, c = bl.shape
    if shape[0] % r or shape[1] % c:
        return None
    top, left = (meta.active_area[0], meta.active_area[1]) if meta.active_area else (0, 0)
    oy, ox = (meta.origin[0] - top) % r, (meta.origin[1] - left) % c
    return np.roll(bl, (-oy, -ox), axis=(0, 1)).astype(np.float32)


@register_stage
class Normalize(Stage):
    """DN -> normalised raw: linearization, per-site black (with deltas), white. No clipping."""

    type = "normalize"
    accepts = frozenset({"raw_dn"})
    produces = "raw"

    class Params(StageParams):
        #: override the file's black level (DN); None uses the metadata
        black_level: Optional[float] = None
        #: override the file's white level (DN); None uses the metadata
        white_level: Optional[float] = None

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        meta = frame.meta
        data = frame.data
        if meta.linearization_table is not None:
            table = np.asarray(meta.linearization_table, dtype=np.float32)
            data = table[np.clip(data, 0, table.size - 1).astype(np.int64)]
        cell = None
        if self.params.black_level is not None:
            black = np.float32(self.params.black_level)
        else:
            cell = black_level_cell(meta, data.shape)
            black = cell if cell is not None else black_level_map(meta, data.shape)
        white = np.float32(self.params.white_level if self.params.white_level is not None else meta.white_level)
        scale = white - black
        if np.any(scale <= 0):
            raise MetadataError(
                f"{meta.source or 'frame'}: WhiteLevel: expected white ({float(white)}) above the black level "
                f"(max {float(np.max(black))})")
        if cell is not None:  # per-site constants: one full-width row pattern per cell row, no H x W map
            (h, w), (r, c) = data.shape, cell.shape
            data = np.asarray(data, dtype=np.float32)
            black_rows, scale_rows = np.tile(cell, (1, w // c)), np.tile(scale, (1, w // c))
            out = np.empty((h, w), dtype=np.float32)
            for i in range(r):  # contiguous rows: SIMD inner loops
                np.subtract(data[i::r], black_rows[i], out=out[i::r])
                np.divide(out[i::r], scale_rows[i], out=out[i::r])
        else:
            out = (data - black) / scale
        return frame.evolve(out.astype(np.float32, copy=False), kind="raw", step=self.type)


def _int_rect(values, what: str, source: str) -> tuple[int, int, int, int]:
    vals = [float(v) for v in values]
    if len(vals) != 4:
        raise StageError(f"{source}: {what}: expected [top, left, bottom, right], got {values!r}")
    return tuple(int(round(v)) for v in vals)  # type: ignore[return-value]


@register_stage
class Crop(Stage):
    """Crop to the active area, the DNG default crop, or an explicit rectangle.

    ``rect`` is ``[top, left, bottom, right]`` in pixels of the current frame
    (bottom/right exclusive). On a mosaic, an odd top or left offset changes
    the CFA phase: ``phase: keep`` (default) refuses such a crop, ``phase:
    update`` accepts it and rewrites ``meta.cfa`` so it describes the data.
    """

    type = "crop"
    accepts = frozenset(SIGNAL_KINDS)

    class Params(StageParams):
        region: Literal["active_area", "default", "explicit"] = "active_area"
        rect: Optional[tuple[int, int, int, int]] = None
        phase: Literal["keep", "update"] = "keep"

    def __init__(self, params=None, **kw):
        super().__init__(params, **kw)
        p = self.params
        if (p.region == "explicit") != (p.rect is not None):
            raise StageError("rect: expected [top, left, bottom, right] exactly when region is 'explicit'")

    def target_rect(self, frame: RawFrame) -> tuple[int, int, int, int]:
        meta, p = frame.meta, self.params
        oy, ox = meta.origin
        if p.region == "explicit":
            return tuple(p.rect)  # type: ignore[return-value]
        if p.region == "active_area":
            if meta.active_area is None:
                return (0, 0, frame.height, frame.width)
            t, l, b, r = meta.active_area
            return (t - oy, l - ox, b - oy, r - ox)
        # DNG DefaultCropOrigin/Size are relative to the active area, (x, y) order.
        at, al = (meta.active_area[0], meta.active_area[1]) if meta.active_area else (0, 0)
        if meta.default_crop_origin is None or meta.default_crop_size is None:
            if meta.active_area is None:
                return (0, 0, frame.height, frame.width)
            t, l, b, r = meta.active_area
            return (t - oy, l - ox, b - oy, r - ox)
        x0, y0 = meta.default_crop_origin
        cw, ch = meta.default_crop_size
        top, left = int(round(at + y0 - oy)), int(round(al + x0 - ox))
        return (top, left, top + int(round(ch)), left + int(round(cw)))

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        top, left, bottom, right = self.target_rect(frame)
        src = frame.meta.source or "frame"
        if not (0 <= top < bottom <= frame.height and 0 <= left < right <= frame.width):
            raise StageError(
                f"{src}: crop ({self.params.region}) rect [{top}, {left}, {bottom}, {right}] "
                f"is outside the {frame.height}x{frame.width} frame")
        meta = frame.meta.copy()
        if frame.kind in MOSAIC_KINDS and meta.cfa is not None and (top % 2 or left % 2):
            if self.params.phase == "keep":
                raise StageError(
                    f"{src}: crop ({self.params.region}) at row {top}, column {left} breaks the CFA phase of "
                    f"{meta.cfa}; expected even offsets, or set phase: update to re-label the pattern")
            meta.cfa = shift_pattern(meta.cfa, top, left)
        meta.origin = (meta.origin[0] + top, meta.origin[1] + left)
        data = np.ascontiguousarray(frame.data[top:bottom, left:right])
        return frame.evolve(data, meta=meta, step=self.type)
