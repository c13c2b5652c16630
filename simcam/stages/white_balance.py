"""``white_balance``: per-channel gains on a mosaic (per CFA site) or on camera RGB.

Gains come from the capture's white (AsShotNeutral, or AsShotWhiteXY through the
colour matrices, DNG 1.6 chapter 6), from an explicit camera ``neutral``
(gains = 1 / neutral), are given directly, or are estimated from the image
(``grey_world``: the mean of every channel is grey, Buchsbaum 1980; ``white_patch``: the
brightest unclipped surfaces are white — a robust max-RGB, Land's retinex white patch, taking
the mean of the brightest ``white_patch_fraction`` of the unclipped 2x2 cells instead of the
single maximum), or from a ``spot`` (a rectangle known to be neutral, as darktable's spot
mode: a grey card); they are normalised so that G = 1.
The gains applied are recorded (multiplied into any earlier ones) in a copy of the
metadata as ``meta.white_balance_gains`` so later colour stages can undo them.
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np

from ..cfa import site_colour_index
from ..colour.dng import DngColorProfile, check_vector, xy_to_camera_neutral
from ..errors import MetadataError, StageError
from ..frame import RawFrame
from .base import RowOp, Stage, StageParams, register_stage


def capture_neutral(meta) -> np.ndarray:
    """The capture's camera neutral (float64, G = 1): AsShotNeutral, else from AsShotWhiteXY."""
    src = meta.source or "metadata"
    if meta.as_shot_neutral is not None:
        n = check_vector(meta.as_shot_neutral, "AsShotNeutral", src)
        return n / n[1]
    if meta.as_shot_white_xy is not None:
        xy = check_vector(meta.as_shot_white_xy, "AsShotWhiteXY", src, n=2)
        return xy_to_camera_neutral(DngColorProfile.from_meta(meta), xy)
    raise MetadataError(f"{src}: AsShotNeutral: missing (and no AsShotWhiteXY); expected the capture's "
                        f"white, or set white_balance neutral: [r, g, b] / gains: [r, g, b]")


def apply_gains(frame: RawFrame, gains: np.ndarray) -> np.ndarray:
    """Multiply the data by per-channel ``gains`` (R, G, B): per CFA site on a mosaic. float32."""
    g = np.asarray(gains, dtype=np.float32)
    if frame.data.ndim == 3:
        return (frame.data * g).astype(np.float32)
    data = np.asarray(frame.data)
    out = np.empty(data.shape, dtype=np.float32)
    mosaic_gain_rows(frame, gains)(data, out, 0)
    return out


def mosaic_gain_rows(frame: RawFrame, gains: np.ndarray):
    """:func:`apply_gains` on a mosaic as a map of rows, ``fn(src, dst, r0)`` (rows ``r0 ..`` into float32
    ``dst``, which may be ``src``)."""
    if frame.meta.cfa is None:
        raise StageError(f"{frame.meta.source or 'frame'}: cfa: a mosaic needs meta.cfa to be white-balanced")
    g = np.asarray(gains, dtype=np.float32)
    idx = site_colour_index(frame.meta.cfa)
    w = np.shape(frame.data)[1]
    rows = [np.resize(g[idx[dy]], w) for dy in range(2)]

    def fn(src: np.ndarray, dst: np.ndarray, r0: int) -> None:
        for dy in range(2):  # one gain row per CFA row: contiguous rows (SIMD loops) instead of strided sites
            k = (dy - r0) % 2  # the first row of this band on CFA row dy
            np.multiply(src[k::2], rows[dy], out=dst[k::2], dtype=np.float32)

    return fn


def cell_rgb(frame: RawFrame) -> np.ndarray:
    """(N, 3) float64 R, G, B of every 2x2 CFA cell (the two greens averaged), or of every pixel of camera RGB."""
    d = np.asarray(frame.data)
    if d.ndim == 3:
        return d.reshape(-1, d.shape[2])[:, :3].astype(np.float64)
    if frame.meta.cfa is None:
        raise StageError(f"{frame.meta.source or 'frame'}: cfa: automatic white balance of a mosaic needs meta.cfa")
    h, w = (d.shape[0] // 2) * 2, (d.shape[1] // 2) * 2
    idx = site_colour_index(frame.meta.cfa)
    out = np.zeros(((h // 2) * (w // 2), 3))
    count = np.zeros(3)
    for dy in range(2):
        for dx in range(2):
            out[:, idx[dy, dx]] += d[dy:h:2, dx:w:2].astype(np.float64).ravel()
            count[idx[dy, dx]] += 1
    return out / count


def estimate_neutral(frame: RawFrame, method: str, *, clip_level: float = 0.98, fraction: float = 0.01) -> np.ndarray:
    """The camera neutral (G = 1) that makes the scene's average (grey world) or its brightest unclipped
    surfaces (white patch) grey; cells with a clipped channel or without signal are left out.

    Raises
    ------
    StageError
        Fewer than 16 usable cells, or a channel without signal.
    """
    rgb = cell_rgb(frame)
    ok = np.isfinite(rgb).all(1) & (rgb.max(1) < clip_level) & (rgb.min(1) > 0)
    src = frame.meta.source or "frame"
    if ok.sum() < 16:
        raise StageError(f"{src}: white_balance {method}: {int(ok.sum())} unclipped cells with signal; expected >= 16")
    use = rgb[ok]
    if method == "white_patch":
        lum = use.sum(1)
        k = max(16, int(np.ceil(fraction * lum.size)))
        use = use[np.argpartition(lum, lum.size - k)[lum.size - k:]]
    neutral = use.mean(0)
    if not (neutral > 0).all():
        raise StageError(f"{src}: white_balance {method}: a channel has no signal (means {neutral.tolist()})")
    return neutral / neutral[1]


@register_stage
class WhiteBalance(Stage, type="white_balance", accepts=frozenset({"raw", "camera_rgb"})):
    """White balance by channel gains (G = 1); records them as ``meta.white_balance_gains``.

    ``source``: ``as_shot`` (the file's white), ``neutral`` (explicit camera neutral,
    gains = 1 / neutral), ``gains`` (explicit), ``none`` (no change). An explicit
    ``neutral`` or ``gains`` given with ``source: as_shot`` overrides the as-shot white.
    """

    class Params(StageParams):
        source: Literal["as_shot", "neutral", "gains", "grey_world", "white_patch", "spot", "none"] = "as_shot"
        #: source: spot: [top, left, bottom, right] in pixels of the frame (a neutral surface)
        spot: Optional[tuple[int, int, int, int]] = None
        #: camera neutral (R, G, B) in stored-value space, > 0; with source: neutral
        neutral: Optional[tuple[float, float, float]] = None
        #: gains (R, G, B), > 0; normalised so G = 1; with source: gains
        gains: Optional[tuple[float, float, float]] = None
        #: auto white balance: cells with any channel at or above this (normalised) level are clipped
        clip_level: float = 0.98
        #: white_patch: share of the brightest unclipped cells averaged as the white
        white_patch_fraction: float = 0.01

    def check_params(self, p) -> None:
        if p.neutral is not None and p.gains is not None:
            raise StageError("white_balance: expected either neutral: [r, g, b] or gains: [r, g, b], not both")
        if p.source == "neutral" and p.neutral is None:
            raise StageError("white_balance: neutral: expected [r, g, b] with source: neutral")
        if p.source == "gains" and p.gains is None:
            raise StageError("white_balance: gains: expected [r, g, b] with source: gains")
        if not 0 < p.clip_level <= 1 or not 0 < p.white_patch_fraction <= 0.5:
            raise StageError(f"white_balance: clip_level in (0, 1] and white_patch_fraction in (0, 0.5] expected, "
                             f"got {p.clip_level}, {p.white_patch_fraction}")
        if (p.source == "spot") != (p.spot is not None):
            raise StageError("white_balance: spot: expected [top, left, bottom, right] with source: spot (and only then)")
        if p.spot is not None and not (0 <= p.spot[0] < p.spot[2] and 0 <= p.spot[1] < p.spot[3]):
            raise StageError(f"white_balance: spot: expected 0 <= top < bottom and 0 <= left < right, got {list(p.spot)}")
        if p.source in ("none", "grey_world", "white_patch", "spot") and (p.neutral is not None or p.gains is not None):
            raise StageError("white_balance: source: none contradicts the neutral/gains given")
        if p.source == "neutral" and p.gains is not None or p.source == "gains" and p.neutral is not None:
            raise StageError(f"white_balance: source: {p.source} contradicts the other of neutral/gains given")
        for name in ("neutral", "gains"):
            v = getattr(p, name)
            if v is not None and not all(np.isfinite(x) and x > 0 for x in v):
                raise StageError(f"white_balance: {name}: expected three finite positive numbers, got {list(v)}")

    @property
    def effective_source(self) -> str:
        """``source``, except that an explicit neutral or gains overrides the as-shot white
        (so ``--set white_balance.neutral=[...]`` works on a pipeline that says as_shot)."""
        p = self.params
        if p.source == "as_shot" and p.neutral is not None:
            return "neutral"
        if p.source == "as_shot" and p.gains is not None:
            return "gains"
        return p.source

    def gains_for(self, frame: RawFrame) -> np.ndarray | None:
        """The gains (R, G, B), G = 1, this stage applies to ``frame`` (None for source: none)."""
        p, source = self.params, self.effective_source
        if source == "none":
            return None
        if source == "gains":
            g = np.asarray(p.gains, dtype=np.float64)
            return g / g[1]
        if source in ("grey_world", "white_patch"):
            neutral = estimate_neutral(frame, source, clip_level=p.clip_level, fraction=p.white_patch_fraction)
        elif source == "spot":
            t, l, b, r = p.spot
            if b > frame.height or r > frame.width:
                raise StageError(f"{frame.meta.source or 'frame'}: white_balance spot {list(p.spot)} outside the "
                                 f"{frame.width}x{frame.height} frame")
            t, l = t - t % 2, l - l % 2  # whole CFA cells
            neutral = estimate_neutral(frame.evolve(np.asarray(frame.data)[t:b, l:r]), "grey_world",
                                       clip_level=p.clip_level)
        else:
            neutral = capture_neutral(frame.meta) if source == "as_shot" else np.asarray(p.neutral, dtype=np.float64)
        return neutral[1] / neutral

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        gains = self.gains_for(frame)
        if gains is None:
            return frame.evolve(step=self.type)
        return frame.evolve(apply_gains(frame, gains), meta=_recorded(frame.meta, gains), step=self.type)

    def row_op(self, frame: RawFrame) -> RowOp | None:
        if self.effective_source in ("none", "grey_world", "white_patch", "spot") or np.ndim(frame.data) != 2:
            return None  # no change, or gains estimated from the pixels
        gains = self.gains_for(frame)
        meta = _recorded(frame.meta, gains)
        return RowOp(mosaic_gain_rows(frame, gains), lambda f, data: f.evolve(data, meta=meta, step=self.type))


def _recorded(meta, gains: np.ndarray):
    """A copy of ``meta`` whose ``white_balance_gains`` include ``gains`` (multiplied into earlier ones)."""
    meta = meta.copy()
    prev = meta.white_balance_gains
    meta.white_balance_gains = gains if prev is None else np.asarray(prev, dtype=np.float64) * gains
    return meta
