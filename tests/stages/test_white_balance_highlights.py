"""Automatic white balance (grey world, white patch) and highlight reconstruction (clip, propagate).

References are closed forms: a scene whose average is grey under a known illuminant gives the
illuminant back; a clipped coloured blob is rebuilt with the colour of its unclipped rim.
"""

from __future__ import annotations

import numpy as np
import pytest

from simcam.frame import CameraMeta, RawFrame
from simcam.stages.highlights import Highlights
from simcam.stages.white_balance import WhiteBalance, estimate_neutral


def mosaic(rgb: np.ndarray, cfa: str = "RGGB") -> np.ndarray:
    idx = {"R": 0, "G": 1, "B": 2}
    out = np.empty(rgb.shape[:2], np.float32)
    for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        out[dy::2, dx::2] = rgb[dy::2, dx::2, idx[cfa[k]]]
    return out


def frame_of(rgb, cfa="RGGB", **meta):
    return RawFrame(mosaic(rgb, cfa), CameraMeta(cfa=cfa, black_level=np.zeros((1, 1)), white_level=1.0, **meta),
                    kind="raw")


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_grey_world_recovers_the_illuminant(cfa):
    rng = np.random.default_rng(1)
    cells = rng.uniform(0.05, 0.9, (32, 48, 3))
    cells *= 0.3 / cells.mean((0, 1))  # the scene's average over the 2x2 cells is grey
    refl = np.repeat(np.repeat(cells, 2, 0), 2, 1)
    illum = np.array([0.55, 1.0, 0.7])
    fr = frame_of((refl * illum * 0.9).astype(np.float32), cfa)
    assert estimate_neutral(fr, "grey_world") == pytest.approx(illum / illum[1], rel=1e-6)
    out = WhiteBalance(source="grey_world")(fr)
    assert out.meta.white_balance_gains == pytest.approx(illum[1] / illum, rel=1e-6)


def test_white_patch_ignores_clipped_cells_and_finds_the_white_surface():
    rng = np.random.default_rng(2)
    refl = rng.uniform(0.05, 0.5, (64, 64, 3)) * np.array([1.0, 0.6, 0.3])  # strongly coloured scene
    refl[:8, :8] = 1.0  # a white card
    illum = np.array([0.8, 1.0, 0.5])
    img = (refl * illum * 0.9).astype(np.float32)
    img[-4:, -4:] = 1.0  # a clipped specular highlight: must not count
    fr = frame_of(img)
    n = estimate_neutral(fr, "white_patch", fraction=0.01)
    assert n == pytest.approx(illum / illum[1], rel=1e-5)
    # grey world is fooled by the coloured scene (the reason for white patch)
    assert not np.allclose(estimate_neutral(fr, "grey_world"), illum / illum[1], rtol=0.05)


def test_auto_white_balance_refuses_an_image_without_usable_cells():
    from simcam.errors import StageError

    fr = frame_of(np.ones((8, 8, 3), np.float32))
    with pytest.raises(StageError, match="unclipped cells"):
        WhiteBalance(source="grey_world")(fr)


def blob_scene(colour=(1.0, 0.5, 0.25), peak=3.0):
    """A coloured surface (white-balanced RGB) whose centre exceeds the clip level in R and G."""
    yy, xx = np.mgrid[0:96, 0:96]
    r2 = ((yy - 48) ** 2 + (xx - 48) ** 2) / 20.0 ** 2
    lum = 0.3 + peak * np.exp(-r2)
    return lum[..., None] * np.asarray(colour)


def test_clip_to_neutral_makes_blown_highlights_white():
    gains = np.array([2.0, 1.0, 1.6])
    true = blob_scene(peak=6.0)  # every channel above 1.0 at the centre
    wb = np.minimum(true, gains)  # each channel clips at its gain after white balance
    fr = frame_of(wb.astype(np.float32), white_balance_gains=gains)
    out = Highlights(method="clip")(fr).data
    assert out.max() <= 1.0 + 1e-6
    centre = out[46:50, 46:50]
    assert np.ptp(centre) < 1e-6  # all sites equal: neutral


def test_propagate_rebuilds_the_surrounding_colour():
    gains = np.array([2.0, 1.0, 1.6])
    colour = np.array([1.0, 0.5, 0.25])
    true = blob_scene(colour)
    wb = np.minimum(true, gains)
    fr = frame_of(wb.astype(np.float32), white_balance_gains=gains)
    out = Highlights(method="propagate")(fr).data
    clipped_cells = (true[0::2, 0::2, 1] > 1.0) & (true[0::2, 0::2, 2] < gains[2])  # G clipped, B not
    assert clipped_cells.sum() > 20
    r, g, b = out[0::2, 0::2], out[0::2, 1::2], out[1::2, 1::2]
    ratio_rg = (r / g)[clipped_cells]
    ratio_bg = (b / g)[clipped_cells]
    # the true ratios are 2.0 and 0.5 everywhere; clipping to neutral would give ~1
    assert np.median(ratio_bg) == pytest.approx(0.5, rel=0.05)
    assert np.median(ratio_rg) == pytest.approx(2.0, rel=0.1)
    assert (out >= np.asarray(fr.data) - 1e-6).all()  # never below the clipped value
    level = mosaic(np.broadcast_to(gains, true.shape).astype(np.float32))
    unclipped = np.asarray(fr.data) < 0.995 * level  # samples below their channel's clip level stay
    assert np.array_equal(out[unclipped], np.asarray(fr.data)[unclipped])


def test_highlights_in_a_pipeline():
    from simcam.pipeline import Pipeline

    p = Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n  - type: white_balance\n"
                           "    source: white_patch\n  - type: highlights\n    method: propagate\n")
    assert [s.type for s in p.stages] == ["normalize", "white_balance", "highlights"]


def test_spot_white_balance_on_the_chart_matches_libraw_patch_means():
    """A spot on the ColorChecker's neutral 5 patch gives the neutral that LibRaw's mosaic shows there."""
    rawpy = pytest.importorskip("rawpy")
    from shared_data import shared_path

    from simcam.io.dng import read_dng
    from simcam.pipeline import Pipeline

    path = shared_path("dng/canon_550d_colorchecker.dng")
    y, x, half = 622 + 102 * 3, int(round(715 + 107.4 * 4)), 18  # neutral 5 (see tests/test_colorchecker.py)
    with rawpy.imread(str(path)) as raw:
        m = raw.raw_image_visible.astype(np.float64)
        colors = raw.raw_colors_visible
        desc = raw.color_desc.decode()
        black = np.asarray(raw.black_level_per_channel, np.float64)[colors]
        norm = (m - black) / (raw.white_level - black)
    box = np.s_[y - half:y + half + 1, x - half:x + half + 1]
    chan = np.array(["RGB".index(desc[c]) for c in range(len(desc))])[colors][box]
    ref = np.array([norm[box][chan == c].mean() for c in range(3)])
    pipe = Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n  - type: crop\n    region: active_area\n"
                              f"  - type: white_balance\n    source: spot\n    spot: [{y - half}, {x - half}, "
                              f"{y + half + 1}, {x + half + 1}]\n")
    out = pipe(read_dng(path))
    assert out.meta.white_balance_gains == pytest.approx(ref[1] / ref, rel=0.01)
