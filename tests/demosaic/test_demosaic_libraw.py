"""Bilinear demosaicing of a real DNG against LibRaw's LINEAR (dcraw ``lin_interpolate``).

LibRaw's bilinear averages the same neighbours as ours (edge neighbours weight 2,
corners weight 1, per colour) on its integer image ``trunc((raw - black) * 65535 /
(white - black))`` and floors the result. With raw colour, linear gamma, unit white
balance, 16-bit output, no auto-brightening and ``adjust_maximum_thr=0`` its output is
``floor(our bilinear of that integer image)`` away from its 1-pixel border (which it
fills with a different rule). All four CFA phases are tested by shifting the window.
"""

from __future__ import annotations

import numpy as np
import pytest

from simcam.cfa import shift_pattern
from simcam.demosaic import demosaic_bilinear

rawpy = pytest.importorskip("rawpy")


@pytest.mark.shared_data
def test_bilinear_equals_libraw_linear_on_canon_550d(shared_file):
    path = shared_file("dng/canon_550d_colorchecker.dng")
    with rawpy.imread(str(path)) as raw:
        assert raw.color_desc == b"RGBG" and raw.raw_pattern.tolist() == [[0, 1], [3, 2]]  # RGGB
        black = float(raw.black_level_per_channel[0])
        assert len(set(raw.black_level_per_channel)) == 1
        white = float(raw.white_level)
        visible = raw.raw_image_visible.astype(np.float64)
        ref = raw.postprocess(
            demosaic_algorithm=rawpy.DemosaicAlgorithm.LINEAR, output_color=rawpy.ColorSpace.raw,
            gamma=(1, 1), no_auto_bright=True, user_wb=[1.0, 1.0, 1.0, 1.0], output_bps=16, user_flip=0,
            highlight_mode=rawpy.HighlightMode.Clip, adjust_maximum_thr=0.0,
        ).astype(np.float64)
    scaled = np.clip(np.trunc((visible - black) * (65535.0 / (white - black))), 0, 65535)
    for dy, dx in [(0, 0), (0, 1), (1, 0), (1, 1)]:
        cfa = shift_pattern("RGGB", dy, dx)
        ours = np.floor(demosaic_bilinear(scaled[dy:, dx:], cfa))
        diff = (ours - ref[dy:, dx:])[1:-1, 1:-1]
        # ~9 of 2e6 values differ by one code (LibRaw's integer path); none by more
        assert np.abs(diff).max() <= 1.0, cfa
        assert np.count_nonzero(diff) < 1e-4 * diff.size, cfa


@pytest.mark.shared_data
def test_malvar_equals_colour_demosaicing_on_real_crop(shared_file):
    cd = pytest.importorskip("colour_demosaicing")
    from simcam.demosaic import demosaic_malvar2004

    path = shared_file("dng/canon_550d_colorchecker.dng")
    with rawpy.imread(str(path)) as raw:
        visible = raw.raw_image_visible.astype(np.float32)
        black, white = float(raw.black_level_per_channel[0]), float(raw.white_level)
    crop = (visible[400:656, 600:856] - black) / (white - black)  # even offsets: still RGGB
    ours = demosaic_malvar2004(crop, "RGGB")
    ref = cd.demosaicing_CFA_Bayer_Malvar2004(crop.astype(np.float64), "RGGB")
    np.testing.assert_allclose(ours[2:-2, 2:-2], ref[2:-2, 2:-2], rtol=1e-5, atol=2e-6)
