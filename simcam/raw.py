"""Raw in: black-level maps and normalisation of sensor DN to normalised raw.

Normalisation maps sensor DN to normalised raw (Adobe DNG Specification 1.7, chapter 5, "Mapping Raw
Values to Linear Reference Values"): linearization table, then black level per CFA site (BlackLevel
with BlackLevelRepeatDim, plus BlackLevelDeltaH/V), then division by (white - black). Negatives are
kept. The ``normalize`` pipeline stage (:class:`simcam.stages.raw.Normalize`) and
:func:`simcam.io.normalized.read_normalized` both run :func:`normalize`.

This module sits just above :mod:`simcam.frame`, below :mod:`simcam.io`: the DNG writer needs
:func:`black_level_map` to de-normalise a frame.
"""

from __future__ import annotations

import numpy as np

from .errors import MetadataError
from .frame import RawFrame


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


def _check_finite_levels(meta, black, white) -> None:
    """Black and white levels must be finite (DNG 1.7.0.0 chapter 5): NaN would reach the image silently."""
    src = meta.source or "frame"
    if not np.isfinite(white):
        raise MetadataError(f"{src}: WhiteLevel: {float(white)}; expected a finite level")
    if not np.all(np.isfinite(black)):
        raise MetadataError(f"{src}: BlackLevel: non-finite value; expected finite levels (BlackLevel, "
                            f"BlackLevelDeltaH/V)")


def _levels(frame: RawFrame, shape: tuple[int, ...], black_level: float | None, white_level: float | None):
    """``(black, cell, scale)``: the black level (a float32 scalar, the per-site cell or the H x W map),
    the cell (or None) and ``white - black``, after the checks of :func:`normalize`."""
    meta = frame.meta
    cell = None
    if black_level is not None:
        black = np.float32(black_level)
    else:
        cell = black_level_cell(meta, shape)
        black = cell if cell is not None else black_level_map(meta, shape)
    white = np.float32(white_level if white_level is not None else meta.white_level)
    _check_finite_levels(meta, black, white)
    scale = white - black
    if np.any(scale <= 0):
        raise MetadataError(
            f"{meta.source or 'frame'}: WhiteLevel: expected white ({float(white)}) above the black level "
            f"(max {float(np.max(black))})")
    return black, cell, scale


def normalize_rows(frame: RawFrame, *, black_level: float | None = None, white_level: float | None = None):
    """:func:`normalize` as a map of rows, ``fn(src, dst, r0)`` (rows ``r0 ..`` of the mosaic into float32
    ``dst``, which may be ``src``), when the black level is one per-site cell and there is no
    linearization table; None otherwise. Raises the errors of :func:`normalize`."""
    meta, shape = frame.meta, np.shape(frame.data)
    if (meta.linearization_table is not None or black_level is not None or len(shape) != 2
            or black_level_cell(meta, shape) is None):  # (not the H x W black map only to drop it)
        return None
    _, cell, scale = _levels(frame, shape, None, white_level)
    return _cell_rows(cell, scale, shape[1])


def _cell_rows(cell: np.ndarray, scale: np.ndarray, w: int):
    """``fn(src, dst, r0)``: rows ``r0 ..`` of a DN mosaic minus the per-site black ``cell``, over ``scale``."""
    r, c = cell.shape
    black_rows, scale_rows = np.tile(cell, (1, w // c)), np.tile(scale, (1, w // c))

    def fn(src: np.ndarray, dst: np.ndarray, r0: int) -> None:
        src = np.asarray(src)
        if src.dtype not in (np.uint8, np.uint16, np.float32):  # exact in float32: cast inside the subtraction
            src = src.astype(np.float32)
        for i in range(r):  # contiguous rows: SIMD inner loops, no float32 copy of the DN mosaic
            k = (i - r0) % r  # the first row of this band whose mosaic row is i modulo the cell
            np.subtract(src[k::r], black_rows[i], out=dst[k::r], dtype=np.float32)
            np.divide(dst[k::r], scale_rows[i], out=dst[k::r])

    return fn


def normalize(frame: RawFrame, *, black_level: float | None = None, white_level: float | None = None) -> RawFrame:
    """DN -> normalised raw: linearization, per-site black (with deltas), white. No clipping.

    Parameters
    ----------
    frame : RawFrame
        A ``raw_dn`` mosaic (as :func:`simcam.io.dng.read_dng` returns).
    black_level, white_level : float, optional
        Override the file's black / white level (DN); None uses the metadata.

    Returns
    -------
    RawFrame
        Kind ``raw``, float32, with ``"normalize"`` appended to its history.

    Raises
    ------
    MetadataError
        When the white level is not above the black level.

    Examples
    --------
    >>> import numpy as np
    >>> from simcam.frame import CameraMeta, RawFrame
    >>> meta = CameraMeta(cfa="RGGB", black_level=np.array([[64.0]]), white_level=1023.0)
    >>> frame = RawFrame(np.array([[64.0, 1023.0], [543.5, 64.0]], np.float32), meta, kind="raw_dn")
    >>> normalize(frame).data.tolist()
    [[0.0, 1.0], [0.5, 0.0]]
    """
    meta = frame.meta
    data = frame.data
    if meta.linearization_table is not None:
        table = np.asarray(meta.linearization_table, dtype=np.float32)
        data = table[np.clip(data, 0, table.size - 1).astype(np.int64)]
    black, cell, scale = _levels(frame, np.shape(data), black_level, white_level)
    if cell is not None:  # per-site constants: one full-width row pattern per cell row, no H x W map
        data = np.asarray(data)
        out = np.empty(data.shape, dtype=np.float32)
        _cell_rows(cell, scale, data.shape[1])(data, out, 0)
    else:
        out = (data - black) / scale
    return frame.evolve(out.astype(np.float32, copy=False), kind="raw", step="normalize")
