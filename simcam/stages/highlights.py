"""``highlights``: reconstruct clipped highlights on a white-balanced mosaic, before demosaicking.

After white balance the channels clip at different levels (a channel with gain g clips at g
times the normalised white). Two methods, as darktable's and RawTherapee's highlight modules
offer them:

* ``clip`` (clip to neutral): every channel is clipped at the lowest clip level, so a blown
  highlight is rendered white instead of magenta or pink;
* ``propagate`` (colour propagation): in a 2x2 cell where some channels are clipped and at
  least one is not, each clipped channel is rebuilt from an unclipped one through the colour
  ratio of the nearest unclipped surroundings (ratios spread inwards by normalised
  convolution at growing scales), never below its clipped value; cells clipped in every
  channel fall back to neutral at the rebuilt brightness of their neighbours, limited to
  the clip level.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..cfa import site_colour_index
from ..errors import StageError
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


def _blur(a: np.ndarray, sigma: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(a, sigma, mode="nearest")


def spread(values: np.ndarray, valid: np.ndarray, *, max_sigma: float = 64.0) -> np.ndarray:
    """Fill ``values`` where ``~valid`` from valid neighbours: normalised convolution at sigma 1, 2, 4, ...

    Each invalid pixel takes the Gaussian-weighted mean of the valid ones at the smallest scale
    that reaches any; pixels no scale reaches keep the global valid mean.
    """
    out = np.where(valid, values, 0.0)
    todo = ~valid
    w = valid.astype(np.float64)
    v = np.where(valid, values, 0.0)
    sigma = 1.0
    while todo.any() and sigma <= max_sigma:
        num, den = _blur(v, sigma), _blur(w, sigma)
        reach = todo & (den > 1e-6)
        out[reach] = num[reach] / den[reach]
        todo &= ~reach
        sigma *= 2.0
    if todo.any():
        out[todo] = values[valid].mean() if valid.any() else 1.0
    return out


@register_stage
class Highlights(Stage, type="highlights", accepts=frozenset({"raw"})):
    """Reconstruct clipped highlights (``method: clip | propagate``) on a white-balanced mosaic."""

    class Params(StageParams):
        method: Literal["clip", "propagate"] = "propagate"
        #: a sample at or above this share of its channel's clip level counts as clipped
        threshold: float = 0.995

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        meta = frame.meta
        src = meta.source or "frame"
        if meta.cfa is None:
            raise StageError(f"{src}: cfa: highlight reconstruction needs a Bayer mosaic")
        if not 0.5 < self.params.threshold <= 1.0:
            raise StageError(f"highlights: threshold: expected a share in (0.5, 1], got {self.params.threshold}")
        gains = np.ones(3) if meta.white_balance_gains is None else np.asarray(meta.white_balance_gains, np.float64)
        levels = gains  # channel c clips at gain_c x the normalised white 1.0
        d = np.asarray(frame.data, dtype=np.float32)
        h, w = (d.shape[0] // 2) * 2, (d.shape[1] // 2) * 2
        idx = site_colour_index(meta.cfa)
        out = d.copy()
        if self.params.method == "clip":
            np.minimum(out, np.float32(levels.min()), out=out)
            return frame.evolve(out, step=self.type)
        sites = [(dy, dx, int(idx[dy, dx])) for dy in range(2) for dx in range(2)]
        planes = {(dy, dx): d[dy:h:2, dx:w:2].astype(np.float64) for dy, dx, _ in sites}
        clipped = {(dy, dx): planes[(dy, dx)] >= self.params.threshold * levels[c] for dy, dx, c in sites}
        any_clip = np.logical_or.reduce(list(clipped.values()))
        if not any_clip.any():
            return frame.evolve(out, step=self.type)
        # per-cell channel values and a reference: the mean of the unclipped green sites, else R or B
        chan = np.zeros((3,) + any_clip.shape)
        chan_ok = np.zeros((3,) + any_clip.shape, bool)
        for c in range(3):
            ps = [(k, planes[k]) for k in planes if int(idx[k]) == c]
            vals = np.mean([p for _, p in ps], axis=0)
            ok = np.logical_and.reduce([~clipped[k] for k, _ in ps])
            chan[c], chan_ok[c] = vals, ok
        all_ok = chan_ok.all(0) & (chan > 0).all(0)
        ratios = np.ones_like(chan)
        for c in (0, 2):  # colour ratios c / G of the unclipped surroundings, spread into clipped cells
            r = np.where(all_ok, chan[c] / np.maximum(chan[1], 1e-12), 1.0)
            ratios[c] = spread(r, all_ok)
        est = chan.copy()
        g_from = np.where(chan_ok[1], chan[1],
                          np.where(chan_ok[0], chan[0] / ratios[0], np.where(chan_ok[2], chan[2] / ratios[2], np.nan)))
        for c in range(3):
            cand = g_from * (ratios[c] if c != 1 else 1.0)
            est[c] = np.where(chan_ok[c], chan[c], np.maximum(chan[c], np.nan_to_num(cand, nan=0.0)))
        none_ok = ~chan_ok.any(0)
        if none_ok.any():  # every channel clipped: neutral at the surroundings' rebuilt level, at most the clip level
            lvl = spread(np.where(~none_ok, est[1], 0.0), ~none_ok)
            neutral = np.minimum(lvl, levels.max())
            for c in range(3):
                est[c] = np.where(none_ok, np.maximum(chan[c], neutral), est[c])
        for dy, dx, c in sites:
            rebuilt = np.where(clipped[(dy, dx)], np.maximum(est[c], planes[(dy, dx)]), planes[(dy, dx)])
            out[dy:h:2, dx:w:2] = rebuilt.astype(np.float32)
        return frame.evolve(out, step=self.type)
