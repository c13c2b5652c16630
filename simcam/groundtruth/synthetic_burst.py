"""Synthetic bursts with known truth, for validation (Abdelhamed 2020, fig. 5.6d / 5.9 set-ups).

The scene is a continuous function per colour (a B-spline surface over random
coefficients plus smooth-edged discs), so any frame's noise-free image is known
exactly under any drift. Frame i sees the scene displaced by a smooth field
``d_i(p) = t_i D(p)`` (an OIS-like coaxial shift plus a radial term, Abdelhamed 2020, section 5.3.3),
scaled by a flicker gain ``g_i``, with hot pixels added, then NLF noise
``var = beta1 y + beta2`` (Abdelhamed 2020, eq. 5.2) and clipping to [clip_low, 1] (eq. 5.3).
Randomness: frame i draws from ``SeedSequence([seed, i])``, dark frame i from ``[seed, 10000 + i]``,
the scene from ``[seed]``, the hot pixels from ``[seed, 999999]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ..cfa import site_colour_index


@dataclass
class SyntheticBurst:
    """A reproducible synthetic burst.

    Parameters
    ----------
    shape : (int, int)
        Mosaic size H x W.
    n : int
        Number of frames.
    cfa : str or None
        Bayer pattern, or None for mono.
    beta1, beta2 : float
        NLF (Abdelhamed 2020, eq. 5.2) on normalised raw.
    drift_px : float
        Largest displacement (mosaic px) between the first and last frame at the image corners.
    global_drift : bool
        Pure translation instead of the spatially varying field.
    flicker_sd : float
        Standard deviation of the per-frame gain around 1.
    outliers : dict
        ``{frame index: gain}`` frames with a gross brightness change (to be dropped).
    hot_fraction : float
        Fraction of pixels with a fixed additive offset (hot pixels).
    hot_range : (float, float)
        Offsets of hot pixels, normalised raw.
    clip_low : float
        Lower clip point (0 as in eq. 5.3; -black/(white-black) for a DNG with a black level).
    level : (float, float)
        Range of the scene before clipping; above 1 gives saturated highlights.
    cell : float
        Feature size of the random texture, mosaic pixels.
    spline_order : int
        Order of the scene's B-spline surface (3 smooth, 1 cheap for huge frames).
    clip : bool
        Clip to [clip_low, 1] (False gives the unclipped oracle burst, same noise draws).
    seed : int
        Seed of the scene, the drift and the noise draws.

    Attributes
    ----------
    fields
        As the parameters; :meth:`frame`, :meth:`truth` and :meth:`dark` draw frame ``i``.

    Examples
    --------
    >>> sb = SyntheticBurst(shape=(16, 16), n=4, drift_px=0.0, seed=2)
    >>> sb.frame(0).shape, bool((sb.truth(0) >= 0).all())
    ((16, 16), True)
    """

    shape: tuple[int, int] = (256, 256)
    n: int = 30
    cfa: str | None = "RGGB"
    beta1: float = 1e-3
    beta2: float = 1e-5
    drift_px: float = 2.0
    global_drift: bool = False
    flicker_sd: float = 0.0
    outliers: dict = field(default_factory=dict)
    hot_fraction: float = 0.0
    hot_range: tuple[float, float] = (0.05, 0.5)
    clip_low: float = 0.0
    level: tuple[float, float] = (0.0, 1.1)
    cell: float = 6.0
    spline_order: int = 3
    clip: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        rng = np.random.default_rng(np.random.SeedSequence([self.seed]))
        H, W = self.shape
        gh, gw = int(np.ceil(H / self.cell)) + 4, int(np.ceil(W / self.cell)) + 4
        base = ndimage.gaussian_filter(rng.standard_normal((gh, gw)), 0.7)
        base = (base - base.min()) / (base.max() - base.min())
        self._coef = []
        for c in range(3):
            tint = 0.6 + 0.4 * rng.random()
            own = ndimage.gaussian_filter(rng.standard_normal((gh, gw)), 0.7)
            own = (own - own.min()) / (own.max() - own.min())
            surf = tint * (0.75 * base + 0.25 * own)
            if self.spline_order > 1:
                surf = ndimage.spline_filter(surf, order=self.spline_order, mode="mirror")
            self._coef.append(surf)
        # smooth-edged discs: (cy, cx, r, amplitude)
        k = 6
        self._discs = np.stack([rng.uniform(0, H, k), rng.uniform(0, W, k), rng.uniform(0.05, 0.2, k) * min(H, W),
                                rng.uniform(-0.4, 0.6, k)], axis=1)
        # drift pattern D(p): coaxial shift + radial term, max |D| = 1 at the corners
        a = rng.uniform(-1, 1, 2)
        self._shift = a / np.linalg.norm(a) * 0.5
        self._radial = rng.choice([-1.0, 1.0]) * 0.5
        self._rot = rng.uniform(-0.3, 0.3)
        self.t = np.linspace(-0.5, 0.5, self.n)
        self.gains = 1.0 + self.flicker_sd * rng.standard_normal(self.n)
        for i, g in self.outliers.items():
            self.gains[int(i)] = float(g)
        rh = np.random.default_rng(np.random.SeedSequence([self.seed, 999_999]))  # sensor: independent of n
        self.hot = rh.random(self.shape) < self.hot_fraction
        self.hot_level = np.where(self.hot, rh.uniform(*self.hot_range, self.shape), 0.0).astype(np.float32)

    # -- geometry ------------------------------------------------------------------------------
    def drift_pattern(self, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
        """D(p) at mosaic coordinates (broadcast arrays) -> (2, ...) displacement per unit t."""
        H, W = self.shape
        if self.global_drift:
            return np.stack(np.broadcast_arrays(self._shift[0] * 2 + 0 * ys, self._shift[1] * 2 + 0 * xs))
        R = 0.5 * np.hypot(H, W)
        u, v = (ys - H / 2) / R, (xs - W / 2) / R
        dy = self._shift[0] + self._radial * u - self._rot * v
        dx = self._shift[1] + self._radial * v + self._rot * u
        return np.stack([dy, dx])

    def drift(self, i: int, ys=None, xs=None) -> np.ndarray:
        """Displacement (2, H, W) of frame i (mosaic px): frame_i(p) = scene(p - d_i(p))."""
        if ys is None:
            ys, xs = np.mgrid[0:self.shape[0], 0:self.shape[1]].astype(np.float64)
        return self.drift_px * self.t[i] * self.drift_pattern(ys, xs)

    # -- signal ---------------------------------------------------------------------------------
    def _scene(self, ys, xs, colour_of) -> np.ndarray:
        H, W = self.shape
        out = np.empty(ys.shape, dtype=np.float64)
        if self.cfa is None:
            cols = np.zeros(ys.shape, dtype=np.int64)
        else:
            cols = colour_of
        gy, gx = ys / self.cell + 2, xs / self.cell + 2
        for c in (range(3) if self.cfa is not None else range(1)):
            sel = cols == c
            if not sel.any():
                continue
            out[sel] = ndimage.map_coordinates(self._coef[c], [gy[sel], gx[sel]], order=self.spline_order,
                                               mode="mirror", prefilter=False)
        for cy, cx, r, amp in self._discs:
            d = np.hypot(ys - cy, xs - cx)
            out += amp * 0.5 * (1 - np.tanh((d - r) / 2.0))
        lo, hi = self.level
        return lo + (hi - lo) * np.clip(out, 0, None) / 1.4

    def truth(self, i: int) -> np.ndarray:
        """Noise-free mosaic of frame i at gain 1 (no hot pixels), float64 H x W."""
        H, W = self.shape
        ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
        d = self.drift(i, ys, xs)
        colour = None
        if self.cfa is not None:
            ci = site_colour_index(self.cfa)
            colour = ci[np.arange(H)[:, None] % 2, np.arange(W)[None, :] % 2]
        return self._scene(ys - d[0], xs - d[1], colour)

    def frame(self, i: int, *, clean: np.ndarray | None = None) -> np.ndarray:
        """Noisy, clipped frame i (float32 normalised raw)."""
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, int(i)]))
        y = (self.truth(i) if clean is None else clean) * self.gains[i] + self.hot_level
        sd = np.sqrt(self.beta1 * np.clip(y, 0, None) + self.beta2)
        x = y + sd * rng.standard_normal(y.shape)
        return (np.clip(x, self.clip_low, 1.0) if self.clip else x).astype(np.float32)

    def dark(self, i: int) -> np.ndarray:
        """Dark frame i (no light): hot pixels plus read noise sqrt(beta2), clipped."""
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 10_000 + int(i)]))
        x = self.hot_level + np.sqrt(self.beta2) * rng.standard_normal(self.shape)
        return np.clip(x, self.clip_low, 1.0).astype(np.float32)


def write_dng_burst(sb: SyntheticBurst, directory, *, black: float = 0.0, white: float = 4095.0, iso: float = 100.0,
                    exposure_time_s: float = 0.01, dark: int = 0, frames=None) -> list:
    """Write the burst's frames (and ``dark`` dark frames) as DNGs ``frame_000.dng``... / ``dark_000.dng``.

    Frames are quantised to DN with ``black``/``white``; ``sb.clip_low`` should
    be ``-black / (white - black)`` so that clipping happens at DN 0 like a sensor.
    Returns the written paths (frames, then darks).
    """
    from pathlib import Path

    from ..frame import CameraMeta, RawFrame
    from ..io.dng_write import write_dng

    if sb.cfa is None:
        raise ValueError("write_dng_burst: DNG needs a Bayer pattern")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    meta = CameraMeta(make="simcam", model="synthetic burst", cfa=sb.cfa, black_level=np.array([[float(black)]]),
                      white_level=float(white), iso=float(iso), exposure_time_s=float(exposure_time_s),
                      noise_profile=np.array([[sb.beta1, sb.beta2]]))
    out = []
    idx = range(sb.n) if frames is None else frames
    for i in idx:
        out.append(write_dng(directory / f"frame_{i:03d}.dng", RawFrame(sb.frame(i), meta, kind="raw")))
    for i in range(dark):
        out.append(write_dng(directory / f"dark_{i:03d}.dng", RawFrame(sb.dark(i), meta, kind="raw")))
    return out
