"""Lens-shading correction from DNG GainMap opcodes (stage ``lens_shading``).

LibRaw does not apply OpcodeList2 (LibRaw's documentation: it does not process DNG opcode lists), so smartphone and
action-camera lens shading is applied here, per Bayer phase, exactly as the
DNG SDK's ``dng_opcode_GainMap`` does (DNG 1.6 spec, section 7, opcode 9;
SDK ``dng_gain_map_interpolator``):

* the opcode list applies to the stage-2 image, i.e. the active area; pixel
  (y, x) below is relative to the active area's top-left;
* a map selects the pixels ``y = Top, Top + RowPitch, ... < Bottom`` and
  ``x = Left, Left + ColPitch, ... < Right`` (so four maps with pitch 2 and
  Top/Left in {0, 1} cover the four Bayer phases) of plane ``Plane`` (a mosaic
  has one plane, so only maps with ``Plane == 0`` apply);
* the map position of a pixel centre is, in relative image coordinates,
  ``v = (y + 0.5) / H``, ``u = (x + 0.5) / W`` (H x W: the active area), and
  its fractional map index ``(v - MapOriginV) / MapSpacingV`` (same for u);
* gains are bilinearly interpolated between map points and clamped to the
  edge points outside the map.

Unlike the SDK, which works on [0, 1] data and clips ``x * gain`` at 1, the
result is not clipped (normalised raw keeps values above 1 and below 0).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from ..errors import MetadataError
from ..frame import CameraMeta, GainMap, RawFrame
from .base import Stage, StageParams, register_stage


def opcode_image_bounds(meta: CameraMeta, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """(top, left, height, width) of the image OpcodeList2 applies to, in stored-image pixels.

    That image is the active area; without an ActiveArea tag it is the whole
    stored image (its size from ``meta.extra["image_size"]``, or the frame's
    shape when ``meta.origin`` is (0, 0)).
    """
    if meta.active_area is not None:
        t, l, b, r = (int(v) for v in meta.active_area)
        return t, l, b - t, r - l
    size = meta.extra.get("image_size") if isinstance(meta.extra, dict) else None
    if size is not None:
        return 0, 0, int(size[0]), int(size[1])
    if tuple(meta.origin) == (0, 0):
        return 0, 0, int(shape[0]), int(shape[1])
    raise MetadataError(
        f"{meta.source or 'frame'}: active_area: None on a frame cropped at origin {tuple(meta.origin)}; "
        f"expected the active area (or extra['image_size']) to place the GainMaps")


def _map_axis(pos: np.ndarray, size: int, origin: float, spacing: float, n: int):
    """Indices (i1, i2) and weights of the DNG SDK interpolator along one axis.

    ``pos`` are pixel positions in the opcode image, ``size`` its extent. The fractional map index
    is clamped to the map (``0 .. n - 1``) before it becomes an integer, so a tiny spacing or a far
    origin selects the edge points (as the SDK's interpolator does) instead of overflowing.
    """
    if n == 1:  # the SDK resets spacing/origin of a 1-point axis
        zeros = np.zeros(pos.shape, dtype=np.int64)
        return zeros, zeros, np.zeros(pos.shape, dtype=np.float64)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        f = ((pos + 0.5) / size - origin) / spacing
    f = np.clip(np.nan_to_num(f, nan=0.0), 0.0, float(n - 1))
    i1 = np.floor(f).astype(np.int64)
    frac = f - i1
    top = i1 >= n - 1
    i1 = np.where(top, n - 1, i1)
    frac = np.where(top, 0.0, frac)
    i2 = np.minimum(i1 + 1, n - 1)
    return i1, i2, frac


def _selection(start: int, stop: int, pitch: int, offset: int, n: int) -> slice | None:
    """Frame indices ``i`` (``0 <= i < n``) whose opcode-image position ``p = i + offset`` is one of
    ``start, start + pitch, ... < stop`` (an area spec's rows or columns, DNG 1.7.0.0 section 7), as a
    slice; None when there is none. O(1): no per-pixel mask."""
    pitch, start, stop = max(int(pitch), 1), int(start), int(stop)
    lo, hi = max(start, offset), min(stop, offset + n)
    first = start + -(-(lo - start) // pitch) * pitch
    if first >= hi:
        return None
    return slice(first - offset, hi - offset, pitch)


def gain_map_patch(gm: GainMap, meta: CameraMeta, shape: tuple[int, int], bounds=None):
    """Rows and columns (slices of the frame) a GainMap touches and its gain there.

    ``bounds`` is :func:`opcode_image_bounds` (computed once per list by callers with many maps).
    Returns ``None`` when the map touches no pixel of the frame, else ``(rows, cols, gain)`` with
    ``gain`` a float for a one-point map (a constant) or a float64 array (len(rows) x len(cols)),
    bilinearly interpolated from map plane ``min(Plane, MapPlanes - 1)``.
    """
    h, w = shape
    at, al, ih, iw = opcode_image_bounds(meta, shape) if bounds is None else bounds
    oy, ox = meta.origin
    rs = _selection(gm.top, gm.bottom, gm.row_pitch, int(oy) - at, h)
    cs = _selection(gm.left, gm.right, gm.col_pitch, int(ox) - al, w)
    if rs is None or cs is None:
        return None
    g = gm.gains
    plane = min(int(gm.plane), g.shape[2] - 1)
    nv, nh = int(g.shape[0]), int(g.shape[1])
    if nv == 1 and nh == 1:
        return rs, cs, float(g[0, 0, plane])
    g = np.asarray(g[:, :, plane], dtype=np.float64)
    y = np.arange(rs.start, rs.stop, rs.step, dtype=np.float64) + (int(oy) - at)
    x = np.arange(cs.start, cs.stop, cs.step, dtype=np.float64) + (int(ox) - al)
    i1, i2, fr = _map_axis(y, ih, gm.map_origin_v, gm.map_spacing_v, nv)
    j1, j2, fc = _map_axis(x, iw, gm.map_origin_h, gm.map_spacing_h, nh)
    # bilinear interpolation is separable: columns on the (few) map rows first, then rows
    gc = g[:, j1] * (1.0 - fc) + g[:, j2] * fc  # (nv, len(cols))
    fr = fr[:, None]
    return rs, cs, gc[i1] * (1.0 - fr) + gc[i2] * fr


def gain_map_selection(gm: GainMap, meta: CameraMeta, shape: tuple[int, int]):
    """Rows, columns (of the frame) a GainMap touches and the gain at each (rows x cols).

    Returns
    -------
    rows, cols : ndarray of int
        Frame indices selected by Top/Bottom/RowPitch and Left/Right/ColPitch.
    gain : ndarray, float64, shape (len(rows), len(cols))
        Bilinearly interpolated map value (plane ``min(Plane, MapPlanes-1)``).
    """
    patch = gain_map_patch(gm, meta, shape)
    if patch is None:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros((0, 0))
    rs, cs, gain = patch
    rows, cols = np.arange(rs.start, rs.stop, rs.step), np.arange(cs.start, cs.stop, cs.step)
    return rows, cols, np.broadcast_to(np.asarray(gain, dtype=np.float64), (rows.size, cols.size))


def _as_slice(idx: np.ndarray, pitch: int) -> slice:
    """The arithmetic progression ``idx`` (step = pitch) as a slice (views, no fancy indexing)."""
    return slice(int(idx[0]), int(idx[-1]) + 1, max(int(pitch), 1))


def gain_field(meta: CameraMeta, shape: tuple[int, int], list_index: int = 2) -> np.ndarray:
    """The total multiplicative gain (H x W, float32) of the mosaic GainMaps of an opcode list."""
    field = np.ones(shape, dtype=np.float64)
    bounds = opcode_image_bounds(meta, shape)
    for gm in meta.gain_maps(list_index):
        if gm.plane != 0:  # a mosaic has a single plane (SDK: plane < buffer.Planes())
            continue
        patch = gain_map_patch(gm, meta, shape, bounds)
        if patch is not None:
            rs, cs, gain = patch
            field[rs, cs] *= gain
    return field.astype(np.float32)


@register_stage
class LensShading(Stage, type="lens_shading", accepts=frozenset({"raw"})):
    """Apply the OpcodeList2 GainMaps (lens-shading / colour-shading correction) to a mosaic.

    ``strength`` blends each gain towards 1: ``g' = 1 + strength * (g - 1)``
    (1 = the file's full correction, 0 = none). Frames without GainMaps pass
    through unchanged.

    ``mode: sidd`` reproduces simple-camera-pipeline (the SIDD renderer) for
    users matching the SIDD benchmark's sRGB: only the FIRST GainMap is used,
    its plane-0 grid is resized to the half-resolution Bayer-cell grid with
    OpenCV's ``INTER_LINEAR`` convention (half-pixel centres, edge clamp) and
    the same gain multiplies all four sites of each cell; the rectangle, pitch
    and map origin/spacing are ignored. A compatibility mode, not the DNG spec.
    """

    class Params(StageParams):
        source: Literal["opcodes"] = "opcodes"
        strength: float = Field(1.0, ge=0.0, le=1.0)
        mode: Literal["dng", "sidd"] = "dng"

    def passes_through(self, frame: RawFrame) -> bool:
        maps = frame.meta.gain_maps(2)
        return not (maps if self.params.mode == "sidd" else [gm for gm in maps if gm.plane == 0])

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        if self.passes_through(frame):
            return frame.evolve(step=f"{self.type}(no GainMaps)")
        if self.params.mode == "sidd":
            return self._apply_sidd(frame)
        maps = [gm for gm in frame.meta.gain_maps(2) if gm.plane == 0]
        s = float(self.params.strength)
        out = np.array(frame.data, dtype=np.float32, copy=True)
        bounds = opcode_image_bounds(frame.meta, out.shape)  # once: a file may hold thousands of maps
        for gm in maps:
            patch = gain_map_patch(gm, frame.meta, out.shape, bounds)
            if patch is not None:
                rs, cs, gain = patch
                out[rs, cs] *= np.float32(1.0 + s * (gain - 1.0)) if np.isscalar(gain) else \
                    (1.0 + s * (gain - 1.0)).astype(np.float32)
        return frame.evolve(out, step=self.type)

    def _apply_sidd(self, frame: RawFrame) -> RawFrame:
        maps = frame.meta.gain_maps(2)
        h2, w2 = frame.height // 2, frame.width // 2
        gain = resize_linear_half_pixel(maps[0].gains[:, :, 0].astype(np.float64), h2, w2)
        gain = (1.0 + float(self.params.strength) * (gain - 1.0)).astype(np.float32)
        out = np.array(frame.data, dtype=np.float32, copy=True)
        for dy in (0, 1):
            for dx in (0, 1):
                out[dy:2 * h2:2, dx:2 * w2:2] *= gain
        return frame.evolve(out, step=f"{self.type}(sidd)")


def resize_linear_half_pixel(src: np.ndarray, h: int, w: int) -> np.ndarray:
    """Bilinear resize of a 2-D grid to ``h x w`` with OpenCV's ``INTER_LINEAR`` mapping.

    Output sample (i, j) reads the source at ``((i + 0.5) * H/h - 0.5, (j + 0.5) * W/w - 0.5)``,
    clamped to the source's edge samples.
    """
    def axis(n_out: int, n_in: int):
        x = np.clip((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5, 0.0, n_in - 1)
        i0 = np.minimum(np.floor(x).astype(np.int64), n_in - 1)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, x - i0

    r0, r1, fr = axis(h, src.shape[0])
    c0, c1, fc = axis(w, src.shape[1])
    top = src[r0][:, c0] * (1 - fc) + src[r0][:, c1] * fc
    bottom = src[r1][:, c0] * (1 - fc) + src[r1][:, c1] * fc
    return top * (1 - fr)[:, None] + bottom * fr[:, None]
