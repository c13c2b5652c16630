"""Acceptance: colour accuracy of the linear-srgb render on a real ColorChecker photograph.

File: canon_550d_colorchecker.dng (Canon EOS 550D, X-Rite ColorChecker Passport, classic
24-patch side; ColorMatrix1 only). White balance for both renders comes from the chart's
neutral patches (neutral 8 .. neutral 3.5), measured on the raw mosaic. Each render is
scaled so that patch "neutral 5" has the reference luminance, then patch means are
compared with colour-science's 'ColorChecker24 - After November 2014' (X-Rite's current
formulation) as CIE Lab under D50 (render: linear sRGB -> XYZ D65 -> Bradford -> D50), by
CIEDE2000. Baseline: rawpy/LibRaw's linear sRGB render with the same white balance.
"""

from __future__ import annotations

import numpy as np
import pytest

from shared_data import shared_path

colour = pytest.importorskip("colour")
rawpy = pytest.importorskip("rawpy")

# Patch-centre grid of this file, in pixels of the active area (1734 x 1156): found by
# rendering the file and looking at it (the chart is upright; 6 columns x 4 rows).
COLS = 715.0 + 107.4 * np.arange(6)
ROWS = 622.0 + 102.0 * np.arange(4)
HALF = 18  # 37 x 37 px box, well inside the ~90 px patches
CENTRES = [(int(round(y)), int(round(x))) for y in ROWS for x in COLS]
NEUTRALS = [19, 20, 21, 22]  # neutral 8, 6.5, 5, 3.5 (white may clip, black is noisy)
NEUTRAL5 = 21
REFERENCE = "ColorChecker24 - After November 2014"
D50 = np.array([0.3457, 0.3585])


def patch_means(img: np.ndarray) -> np.ndarray:
    return np.array([img[y - HALF:y + HALF + 1, x - HALF:x + HALF + 1].reshape(-1, img.shape[-1]).mean(0)
                     for y, x in CENTRES])


def neutral_from_raw(path) -> np.ndarray:
    """Camera neutral (R, G, B), G = 1, of the neutral patches, from LibRaw's visible mosaic."""
    with rawpy.imread(str(path)) as raw:
        mosaic = raw.raw_image_visible.astype(np.float64)
        colors = raw.raw_colors_visible.copy()
        desc = raw.color_desc.decode()
        black = np.asarray(raw.black_level_per_channel, dtype=np.float64)[colors]
        white = float(raw.white_level)
    norm = (mosaic - black) / (white - black)
    chan = np.array(["RGB".index(desc[c]) for c in range(len(desc))])[colors]
    sums = np.zeros(3)
    for k in NEUTRALS:
        y, x = CENTRES[k]
        box = np.s_[y - HALF:y + HALF + 1, x - HALF:x + HALF + 1]
        sums += [norm[box][chan[box] == c].mean() for c in range(3)]
    return sums / sums[1]


def rawpy_linear_srgb(path, gains: np.ndarray) -> np.ndarray:
    with rawpy.imread(str(path)) as raw:
        desc = raw.color_desc.decode()
        user_wb = [float(gains["RGB".index(c)]) for c in desc]  # rawpy indexes color_desc, e.g. RGBG
        out = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=False,
                              user_wb=user_wb, output_color=rawpy.ColorSpace.sRGB, user_flip=0,
                              demosaic_algorithm=rawpy.DemosaicAlgorithm.AHD)
    return out.astype(np.float64) / 65535.0


def mean_delta_e(linear_srgb: np.ndarray) -> tuple[float, np.ndarray]:
    cc = colour.CCS_COLOURCHECKERS[REFERENCE]
    ref_xyz = colour.xyY_to_XYZ(np.array(list(cc.data.values())))
    ref_lab = colour.XYZ_to_Lab(ref_xyz, cc.illuminant)
    xyz = colour.RGB_to_XYZ(patch_means(linear_srgb), "sRGB", illuminant=D50,
                            chromatic_adaptation_transform="Bradford")
    xyz = xyz * (ref_xyz[NEUTRAL5, 1] / xyz[NEUTRAL5, 1])
    de = colour.delta_E(colour.XYZ_to_Lab(xyz, D50), ref_lab, method="CIE 2000")
    return float(de.mean()), de


def test_colorchecker_linear_srgb_beats_or_matches_rawpy():
    pytest.importorskip("simcam.io.dng")
    pytest.importorskip("simcam.stages.demosaic")
    from simcam.io.dng import read_dng
    from simcam.pipeline import Pipeline

    path = shared_path("dng/canon_550d_colorchecker.dng")
    neutral = neutral_from_raw(path)
    pipe = Pipeline.from_yaml("linear-srgb").with_overrides(
        {"white_balance.source": "neutral", "white_balance.neutral": neutral.tolist()})
    ours = pipe(read_dng(path)).data
    theirs = rawpy_linear_srgb(path, 1.0 / neutral)
    assert ours.shape == theirs.shape == (1156, 1734, 3)
    de_ours, per_ours = mean_delta_e(ours)
    de_rawpy, per_rawpy = mean_delta_e(theirs)
    print(f"\nmean CIEDE2000 over 24 patches (Lab D50, {REFERENCE}): "
          f"simcam {de_ours:.2f}, rawpy {de_rawpy:.2f}")
    assert 2.0 < de_rawpy < 8.0  # the measurement itself is sane (rawpy measured about 5)
    assert de_ours <= de_rawpy
