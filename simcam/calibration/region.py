"""The pixels the loop's residual battery and bootstrap analyse: the whole frame, or tiles spread over it.

The cost of the loop is its parametric bootstrap (``replicates`` simulated captures per evaluation,
each reduced to the diagnostics), which grows with the pixels analysed. Frames up to
``max_pixels`` are analysed whole. Larger frames are analysed as a *mosaic* of ``tile`` x ``tile``
tiles on a regular ``gy`` x ``gx`` grid spanning the whole frame (the most tiles whose pixels fit in
``max_pixels``), stitched in grid order; the bootstrap simulates the same mosaic, so every
statistic's null has exactly the data's pixel count and no scaling is needed. What a mosaic keeps
and what it does not:

* tile origins are even, so each tile keeps the CFA phase of the frame;
* a mosaic row is one sensor row restricted to the ``gx`` tiles of its grid row (row noise, row
  offsets kept); a mosaic column is one sensor column restricted to ``gy`` tiles (column FPN kept);
* per-pixel statistics (DSNU, PRNU, hot pixels, tails, code occupancy) see a uniform sample of the
  frame's pixels; spatial correlation (lags 1-2 inside a plane) is unaffected except at the
  ``gx - 1`` + ``gy - 1`` tile seams;
* a periodic row / column pattern is sampled with phase jumps at the seams, which spreads its
  spectral line (the peak statistics lose power for patterns whose period does not divide the grid
  spacing).

Whole-frame figures (EMVA 1288 numbers, dark current) do not use the mosaic: the reader streams every
frame through per-sequence accumulators (:mod:`simcam.calibration.capture`).

``max_size`` (the ``--max-size`` option) replaces the mosaic by a centre crop of at most
``max_size`` pixels per side, as earlier versions of the loop did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: default pixel budget of the analysed region (the whole frame up to this size).
DEFAULT_MAX_PIXELS = 448 * 448
#: default tile side of a mosaic (even).
DEFAULT_TILE = 128


@dataclass(frozen=True)
class Region:
    """Which pixels of an ``H x W`` frame the loop analyses (module docstring)."""

    max_pixels: int = DEFAULT_MAX_PIXELS
    tile: int = DEFAULT_TILE
    max_size: int | None = None

    def plan(self, h: int, w: int) -> tuple[list[int], list[int], int, int]:
        """(tile row origins, tile column origins, tile height, tile width); one tile when the frame
        (or its centre crop) is analysed whole."""
        if self.max_size is not None:
            ch, cw = min(h, self.max_size), min(w, self.max_size)
            ch, cw = ch - ch % 2, cw - cw % 2
            return [((h - ch) // 2) // 2 * 2], [((w - cw) // 2) // 2 * 2], ch, cw
        if h * w <= self.max_pixels:
            return [0], [0], h - h % 2, w - w % 2
        t = max(2, self.tile - self.tile % 2)
        th, tw = min(t, h - h % 2), min(t, w - w % 2)
        n_max = max(1, self.max_pixels // (th * tw))
        ny_all, nx_all = max(1, h // th), max(1, w // tw)
        # grid as square as the frame's aspect allows, within the budget
        gy = max(1, min(ny_all, int(round(np.sqrt(n_max * h / w)))))
        gx = max(1, min(nx_all, n_max // gy))
        gy = max(1, min(ny_all, n_max // gx))
        ys = _spread(h, th, gy)
        xs = _spread(w, tw, gx)
        return ys, xs, th, tw

    def extract(self, frames: np.ndarray, plan=None) -> np.ndarray:
        """The analysed pixels of ``frames`` (..., H, W) as one array (..., gy * th, gx * tw)."""
        ys, xs, th, tw = plan or self.plan(*frames.shape[-2:])
        if len(ys) == 1 and len(xs) == 1:
            return frames[..., ys[0]:ys[0] + th, xs[0]:xs[0] + tw]
        rows = [np.concatenate([frames[..., y:y + th, x:x + tw] for x in xs], axis=-1) for y in ys]
        return np.concatenate(rows, axis=-2)

    def describe(self, h: int, w: int) -> dict:
        """What is analysed, for the report: pixels, fraction of the frame, layout in words."""
        ys, xs, th, tw = self.plan(h, w)
        n = len(ys) * len(xs) * th * tw
        if len(ys) * len(xs) == 1:
            how = "whole frame" if (th, tw) == (h - h % 2, w - w % 2) else f"centre crop {tw} x {th}"
        else:
            how = f"{len(ys) * len(xs)} tiles of {tw} x {th} on a {len(xs)} x {len(ys)} grid spanning the frame"
        return {"frame": [int(w), int(h)], "pixels_analysed": int(n), "fraction": n / float(h * w), "layout": how}


def _spread(size: int, t: int, n: int) -> list[int]:
    """``n`` even tile origins spread evenly over [0, size - t]."""
    if n <= 1:
        return [((size - t) // 2) // 2 * 2]
    return [int(round(k * (size - t) / (n - 1))) // 2 * 2 for k in range(n)]
