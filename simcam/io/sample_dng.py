"""Small synthetic DNGs for tests, examples and fixtures.

:func:`synthetic_meta` builds a plausible :class:`CameraMeta` (colour matrices
of a real camera profile, illuminants A / D65, an as-shot neutral, a
NoiseProfile) and :func:`make_test_dng` writes a deterministic mosaic with it
through :func:`simcam.io.dng_write.write_dng`. Every field can be overridden.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..frame import CameraMeta, GainMap, Opcode

# A real camera's DNG calibration (GoPro HERO7 Black, public gpr sample files):
# ColorMatrix1 under Tungsten (CalibrationIlluminant 3), ColorMatrix2 under D50 (23).
_CM_TUNGSTEN = np.array([[1.8331, -0.8166, -0.2478], [0.1391, 0.8961, -0.0367], [0.0822, 0.0662, 0.2597]])
_CM_D50 = np.array([[1.0344, -0.4210, -0.0620], [-0.2315, 1.0625, 0.1948], [0.0093, 0.1058, 0.5541]])


def synthetic_meta(cfa: str = "RGGB", *, black: float = 64.0, white: float = 1023.0, minimal: bool = False,
                   **fields: Any) -> CameraMeta:
    """A plausible :class:`CameraMeta` for synthetic data.

    Parameters
    ----------
    cfa : str
        Bayer pattern of pixel (0, 0).
    black, white : float
        Black level (DN, one value) and white level (DN).
    minimal : bool
        Only CFA and levels (no colour matrices, neutral, noise profile).
    **fields
        Any other :class:`CameraMeta` field, overriding the defaults.
    """
    base: dict[str, Any] = dict(
        make="simcam", model="synthetic", unique_camera_model="simcam synthetic", cfa=cfa,
        black_level=np.full((1, 1), float(black)), white_level=float(white),
    )
    if not minimal:
        base.update(
            color_matrix1=_CM_TUNGSTEN.copy(), color_matrix2=_CM_D50.copy(),
            calibration_illuminant1=3, calibration_illuminant2=23,
            as_shot_neutral=np.array([0.5, 1.0, 0.625]),
            noise_profile=np.array([[2.0e-4, 1.0e-6]]),
            iso=100.0, exposure_time_s=0.01,
        )
    base.update(fields)
    return CameraMeta(**base)


def radial_gain_maps(h: int, w: int, *, points: tuple[int, int] = (9, 11), strength: float = 0.5,
                     top: int = 0, left: int = 0) -> list[Opcode]:
    """Four GainMap opcodes (one per Bayer phase) of a radial vignetting correction.

    Gain ``1 + strength * r^2`` with r the distance to the centre in relative
    units (0 centre, 1 corner). Map rectangles start at ``(top, left)`` of the
    active area and cover ``h x w`` pixels.
    """
    from .opcodes import gain_map_opcode

    pv, ph = points
    v = np.linspace(0.0, 1.0, pv)[:, None] - 0.5
    u = np.linspace(0.0, 1.0, ph)[None, :] - 0.5
    r2 = (v ** 2 + u ** 2) / 0.5
    ops = []
    for dy, dx in ((0, 0), (0, 1), (1, 0), (1, 1)):
        gains = (1.0 + strength * r2 * (1.0 + 0.05 * (2 * dy + dx)))[:, :, None].astype(np.float32)
        gm = GainMap(top=top + dy, left=left + dx, bottom=top + h, right=left + w, plane=0, planes=1,
                     row_pitch=2, col_pitch=2, map_spacing_v=1.0 / (pv - 1), map_spacing_h=1.0 / (ph - 1),
                     map_origin_v=0.0, map_origin_h=0.0, gains=gains)
        ops.append(gain_map_opcode(gm))
    return ops


def synthetic_mosaic(h: int, w: int, meta: CameraMeta, *, seed: int = 0, level: float = 0.4) -> np.ndarray:
    """A deterministic H x W mosaic in DN: a smooth gradient plus Poisson-like noise, within black..white."""
    rng = np.random.default_rng(seed)
    black = float(np.mean(meta.black_level))
    span = float(meta.white_level) - black
    yy, xx = np.mgrid[0:h, 0:w]
    signal = level * (0.5 + 0.5 * (yy / max(h - 1, 1)) * (xx / max(w - 1, 1)))
    dn = black + span * signal + rng.normal(0.0, 1.0, (h, w)) * np.sqrt(np.maximum(span * signal, 1.0) * 0.5)
    return np.clip(np.round(dn), 0, float(meta.white_level)).astype(np.float32)


def make_test_dng(path: str | os.PathLike, h: int = 32, w: int = 32, cfa: str = "RGGB", *,
                  data: np.ndarray | None = None, seed: int = 0, black: float = 64.0, white: float = 1023.0,
                  minimal: bool = False, **meta_fields: Any) -> Path:
    """Write a small synthetic CFA DNG and return its path.

    Parameters
    ----------
    path : path-like
        Output file.
    h, w : int
        Size in pixels (LibRaw/rawpy only opens images of 22 px or more a
        side; :func:`simcam.io.dng.read_dng` reads smaller ones directly).
    cfa : str
        Bayer pattern of pixel (0, 0).
    data : ndarray, optional
        DN values (H x W); default :func:`synthetic_mosaic`.
    seed : int
        Seed of the default mosaic.
    black, white, minimal, **meta_fields
        Passed to :func:`synthetic_meta`.
    """
    from .dng_write import write_dng

    meta = synthetic_meta(cfa, black=black, white=white, minimal=minimal, **meta_fields)
    if data is None:
        data = synthetic_mosaic(h, w, meta, seed=seed)
    return write_dng(path, np.asarray(data), meta)
