"""Raw-domain stages: ``normalize`` and ``crop``.

``normalize`` maps sensor DN to normalised raw with :func:`simcam.raw.normalize`
(Adobe DNG Specification 1.7, chapter 5, "Mapping Raw Values to Linear Reference
Values"): linearization table, then black level per CFA site, then division by
(white - black). Negatives are kept.
"""

from __future__ import annotations

import math
from typing import Literal, Optional

import numpy as np

from ..cfa import shift_pattern
from ..errors import StageError
from ..frame import MOSAIC_KINDS, SIGNAL_KINDS, RawFrame
from ..raw import normalize, normalize_rows
from .base import RowOp, Stage, StageParams, register_stage


@register_stage
class Normalize(Stage, type="normalize", accepts=frozenset({"raw_dn"}), produces="raw"):
    """DN -> normalised raw: linearization, per-site black (with deltas), white. No clipping."""

    class Params(StageParams):
        #: override the file's black level (DN); None uses the metadata
        black_level: Optional[float] = None
        #: override the file's white level (DN); None uses the metadata
        white_level: Optional[float] = None

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        return normalize(frame, black_level=self.params.black_level, white_level=self.params.white_level)

    def row_op(self, frame: RawFrame) -> RowOp | None:
        fn = normalize_rows(frame, black_level=self.params.black_level, white_level=self.params.white_level)
        return None if fn is None else RowOp(fn, lambda f, data: f.evolve(data, kind="raw", step="normalize"))


def _int_rect(values, what: str, source: str) -> tuple[int, int, int, int]:
    vals = [float(v) for v in values]
    if len(vals) != 4:
        raise StageError(f"{source}: {what}: expected [top, left, bottom, right], got {values!r}")
    return tuple(int(round(v)) for v in vals)  # type: ignore[return-value]


def _finite_pair(values, tag: str, source: str) -> tuple[float, float]:
    """A DNG (x, y) pair as two finite floats, or a StageError naming the file and the tag."""
    try:
        x, y = (float(v) for v in values)
    except (TypeError, ValueError):
        raise StageError(f"{source or 'frame'}: {tag}: {values!r}; expected two numbers (x, y)") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise StageError(f"{source or 'frame'}: {tag}: ({x}, {y}); expected finite numbers")
    return x, y


@register_stage
class Crop(Stage, type="crop", accepts=frozenset(SIGNAL_KINDS)):
    """Crop to the active area, the DNG default crop, or an explicit rectangle.

    ``rect`` is ``[top, left, bottom, right]`` in pixels of the current frame
    (bottom/right exclusive). On a mosaic, an odd top or left offset changes
    the CFA phase: ``phase: keep`` (default) refuses such a crop, ``phase:
    update`` accepts it and rewrites ``meta.cfa`` so it describes the data.
    """

    class Params(StageParams):
        region: Literal["active_area", "default", "explicit"] = "active_area"
        rect: Optional[tuple[int, int, int, int]] = None
        phase: Literal["keep", "update"] = "keep"

    def check_params(self, p) -> None:
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
        x0, y0 = _finite_pair(meta.default_crop_origin, "DefaultCropOrigin", meta.source)
        cw, ch = _finite_pair(meta.default_crop_size, "DefaultCropSize", meta.source)
        top, left = int(round(at + y0 - oy)), int(round(al + x0 - ox))
        return (top, left, top + int(round(ch)), left + int(round(cw)))

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        (top, left, bottom, right), meta = self.plan(frame)
        data = np.ascontiguousarray(frame.data[top:bottom, left:right])
        return frame.evolve(data, meta=meta, step=self.type)

    def plan(self, frame: RawFrame):
        """The rectangle ``(top, left, bottom, right)`` this crop takes from ``frame`` and the metadata
        of the result (the checks of :meth:`apply`, without touching the pixels)."""
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
        return (top, left, bottom, right), meta
