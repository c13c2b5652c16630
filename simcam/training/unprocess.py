"""Unprocessing sRGB images to raw (after Brooks et al. 2019, "Unprocessing images for
learned raw denoising", CVPR, doi:10.1109/CVPR.2019.01129).

Inverts, in order: a global smoothstep tone curve, the sRGB-like 2.2 gamma,
the colour correction (camera RGB -> linear sRGB), the white-balance and
brightness gains (with Brooks' highlight-preserving "safe" inverse gain),
then samples a Bayer mosaic. Random parameters are drawn from ``rng`` by
:meth:`Unprocess.sample`; :meth:`Unprocess.apply` is deterministic.
Units: input display sRGB in [0, 1]; output normalised raw mosaic.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..cfa import PACK_OFFSETS, check_pattern
from ..errors import DatasetError

#: linear sRGB (D65) -> XYZ, IEC 61966-2-1.
SRGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                        [0.2126729, 0.7151522, 0.0721750],
                        [0.0193339, 0.1191920, 0.9503041]])


def inverse_smoothstep(y: np.ndarray) -> np.ndarray:
    """Inverse of ``3x^2 - 2x^3`` on [0, 1]: ``0.5 - sin(asin(1 - 2y) / 3)``."""
    y = np.clip(y, 0.0, 1.0)
    return 0.5 - np.sin(np.arcsin(1.0 - 2.0 * y) / 3.0)


def inverse_gamma(x: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """``max(x, 1e-8) ** gamma``."""
    return np.maximum(x, 1e-8) ** gamma


def mosaic(rgb: np.ndarray, cfa: str = "RGGB") -> np.ndarray:
    """H x W x 3 -> H x W Bayer mosaic (H, W even)."""
    cfa = check_pattern(cfa)
    h, w = rgb.shape[:2]
    if h % 2 or w % 2:
        raise DatasetError(f"mosaic: height and width must be even, got {h}x{w}")
    out = np.empty((h, w), dtype=rgb.dtype)
    for (dy, dx), c in zip(PACK_OFFSETS, cfa):
        out[dy::2, dx::2] = rgb[dy::2, dx::2, "RGB".index(c)]
    return out


@dataclass
class Unprocess:
    """Random unprocessing of sRGB crops (Brooks et al. 2019, section 3).

    Parameters
    ----------
    xyz_to_cam : list of 3x3 arrays, optional
        Camera ColorMatrices (XYZ -> camera, DNG ColorMatrix); a random convex
        combination is used per sample. None: camera RGB = linear sRGB.
    red_gain, blue_gain : (lo, hi)
        Uniform ranges of the white-balance gains (Brooks: 1.9-2.4, 1.5-1.9).
    brightness_mean, brightness_std : float
        ``1 / N(mean, std)`` global gain (Brooks: 0.8, 0.1).
    cfa : str
        Pattern of the produced mosaic.
    """

    xyz_to_cam: Sequence[np.ndarray] | None = None
    red_gain: tuple[float, float] = (1.9, 2.4)
    blue_gain: tuple[float, float] = (1.5, 1.9)
    brightness_mean: float = 0.8
    brightness_std: float = 0.1
    cfa: str = "RGGB"

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        if self.xyz_to_cam:
            w = rng.uniform(1e-8, 1.0, len(self.xyz_to_cam))
            xyz2cam = sum(wi * np.asarray(m, np.float64) for wi, m in zip(w / w.sum(), self.xyz_to_cam))
            rgb2cam = xyz2cam @ SRGB_TO_XYZ
            rgb2cam = rgb2cam / rgb2cam.sum(axis=1, keepdims=True)
        else:
            rgb2cam = np.eye(3)
        rgb_gain = 1.0 / max(rng.normal(self.brightness_mean, self.brightness_std), 0.1)
        return {"rgb2cam": rgb2cam, "red_gain": float(rng.uniform(*self.red_gain)),
                "blue_gain": float(rng.uniform(*self.blue_gain)), "rgb_gain": float(rgb_gain)}

    def apply(self, srgb: np.ndarray, drawn: dict[str, Any]) -> np.ndarray:
        """Display sRGB H x W x 3 in [0, 1] -> normalised raw mosaic H x W (float32)."""
        x = inverse_gamma(inverse_smoothstep(np.asarray(srgb, np.float32)))
        x = np.clip(x @ np.asarray(drawn["rgb2cam"], np.float32).T, 0.0, 1.0)
        gains = np.array([1.0 / drawn["red_gain"], 1.0, 1.0 / drawn["blue_gain"]], np.float32) / drawn["rgb_gain"]
        gray = x.mean(axis=-1, keepdims=True)
        inflection = 0.9
        mask = (np.maximum(gray - inflection, 0.0) / (1.0 - inflection)) ** 2
        safe = np.maximum(mask + (1.0 - mask) * gains, gains)
        return mosaic(np.clip(x * safe, 0.0, 1.0), self.cfa).astype(np.float32)

    def __call__(self, srgb: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict[str, Any]]:
        drawn = self.sample(rng)
        return self.apply(srgb, drawn), drawn
