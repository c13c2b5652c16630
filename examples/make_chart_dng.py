"""Synthesise the bundled example DNG: a ColorChecker scene seen by a simulated camera.

The scene is the 24-patch ColorChecker (colour-science's "After November 2014" xyY
values, D50) adapted to a D65 illuminant, seen through a camera whose XYZ -> camera
matrix is the published Adobe matrix of the Canon EOS 550D (dcraw's adobe_coeff table,
D65). The frame carries lens-shading fall-off that its own DNG GainMap opcodes undo,
Poisson-Gaussian noise matching its NoiseProfile tag, black 256 and white 4095 (12 bit).

Run ``python examples/make_chart_dng.py [OUT.dng]`` to regenerate
``examples/data/chart.dng`` (deterministic: fixed seed).
"""

from __future__ import annotations

import sys
from pathlib import Path

import colour
import numpy as np

from simcam.frame import CameraMeta, GainMap
from simcam.io.dng_write import write_dng
from simcam.io.opcodes import gain_map_opcode

H, W = 400, 600
BLACK, WHITE = 256.0, 4095.0
#: XYZ (D65) -> camera, Canon EOS 550D, Adobe DNG Converter matrix as listed by dcraw.
COLOR_MATRIX = np.array([[6941, -1164, -857], [-3825, 11597, 2534], [-416, 1540, 6039]]) / 10000.0
BETA1, BETA2 = 2.0e-4, 4.0e-6  # NLF of normalised raw: var = BETA1 * x + BETA2


def chart_xyz_d65() -> np.ndarray:
    """24 x 3 XYZ of the chart patches under D65 (Bradford-adapted from D50), Y of white ~0.9."""
    cc = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    xyz_d50 = colour.xyY_to_XYZ(np.array(list(cc.data.values())))
    d50 = colour.xy_to_XYZ(cc.illuminant)
    d65 = colour.xy_to_XYZ(colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])
    return colour.adaptation.chromatic_adaptation_VonKries(xyz_d50, d50, d65, transform="Bradford")


def scene_camera_rgb() -> np.ndarray:
    """H x W x 3 camera RGB of the chart on a dark-grey surround (linear, white ~0.85)."""
    cam = chart_xyz_d65() @ COLOR_MATRIX.T
    img = np.empty((H, W, 3))
    img[:] = (0.10 * np.array([0.95047, 1.0, 1.08883])) @ COLOR_MATRIX.T
    ph, pw, gap = 80, 80, 12
    y0, x0 = (H - (4 * ph + 3 * gap)) // 2, (W - (6 * pw + 5 * gap)) // 2
    for k in range(24):
        r, c = divmod(k, 6)
        y, x = y0 + r * (ph + gap), x0 + c * (pw + gap)
        img[y:y + ph, x:x + pw] = cam[k]
    return img


def vignette_gain_maps(n: int = 9) -> list[GainMap]:
    """Four GainMaps (one per Bayer phase) that undo a cos^4-like fall-off."""
    v = np.linspace(0.0, 1.0, n)
    yy, xx = np.meshgrid(v, v, indexing="ij")
    r2 = (yy - 0.5) ** 2 + (xx - 0.5) ** 2
    gain = (1.0 + 1.2 * r2).astype(np.float32)  # centre 1.0, corners 1.6
    maps = []
    for dy in (0, 1):
        for dx in (0, 1):
            maps.append(GainMap(top=dy, left=dx, bottom=H, right=W, plane=0, planes=1,
                                row_pitch=2, col_pitch=2, map_spacing_v=1.0 / (n - 1),
                                map_spacing_h=1.0 / (n - 1), map_origin_v=0.0, map_origin_h=0.0,
                                gains=gain[:, :, None].copy()))
    return maps


def make(out: Path, seed: int = 20261121) -> Path:
    rng = np.random.default_rng(seed)
    cam = scene_camera_rgb()
    neutral = np.array([0.95047, 1.0, 1.08883]) @ COLOR_MATRIX.T
    neutral = neutral / neutral[1]
    mosaic = np.empty((H, W))
    mosaic[0::2, 0::2] = cam[0::2, 0::2, 0]  # RGGB
    mosaic[0::2, 1::2] = cam[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = cam[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = cam[1::2, 1::2, 2]
    mosaic *= 0.85 / cam[..., 1].max()
    maps = vignette_gain_maps()
    # Bake in the fall-off the gain maps correct (evaluated on the map grid, bilinear).
    yy, xx = np.meshgrid(np.linspace(0, 1, H), np.linspace(0, 1, W), indexing="ij")
    mosaic /= 1.0 + 1.2 * ((yy - 0.5) ** 2 + (xx - 0.5) ** 2)
    noisy = rng.poisson(np.clip(mosaic, 0, None) / BETA1) * BETA1 + rng.normal(0, np.sqrt(BETA2), mosaic.shape)
    dn = np.clip(np.round(noisy * (WHITE - BLACK) + BLACK), 0, WHITE).astype(np.uint16)
    meta = CameraMeta(
        make="simcam", model="synthetic chart", unique_camera_model="simcam synthetic chart",
        cfa="RGGB", black_level=np.full((2, 2), BLACK), white_level=WHITE,
        as_shot_neutral=neutral, color_matrix1=COLOR_MATRIX, calibration_illuminant1=21,
        noise_profile=np.array([[BETA1, BETA2]]), iso=100.0, exposure_time_s=0.01,
        orientation=1, active_area=(0, 0, H, W),
        opcode_list2=[gain_map_opcode(m) for m in maps],
    )
    return write_dng(out, dn, meta)


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent / "data" / "chart.dng"
    print(make(target))
