"""lens_shading stage vs an independent per-pixel evaluation of the DNG GainMap formula.

Reference (DNG 1.6 spec, opcode 9 GainMap; DNG SDK dng_gain_map_interpolator):
pixel (y, x) of the active-area image is touched by a map when
Top <= y < Bottom, (y - Top) % RowPitch == 0 (same for columns) and Plane == 0;
its map coordinate is fy = ((y + 0.5) / H - MapOriginV) / MapSpacingV (H the
active-area height), clamped to [0, MapPointsV - 1]; same for x; the gain is the
bilinear interpolation of the four surrounding map points.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from shared_data import shared_path
from simcam.errors import StageError
from simcam.frame import RawFrame
from simcam.io.dng import read_dng_meta
from simcam.io.sample_dng import radial_gain_maps, synthetic_meta
from simcam.pipeline import Pipeline  # noqa: F401  (the stage must be registered for pipelines)
from simcam.stages.base import get_stage_class
from simcam.stages.lens_shading import LensShading, gain_field


def _axis(pos, size, origin, spacing, n):
    if n == 1:
        return 0, 0, 0.0
    f = ((pos + 0.5) / size - origin) / spacing
    if f <= 0:
        return 0, 0, 0.0
    i = int(math.floor(f))
    if i >= n - 1:
        return n - 1, n - 1, 0.0
    return i, i + 1, f - i


def reference_gain(meta, row, col):
    """Total gain at frame pixel (row, col), one pixel at a time (plain Python)."""
    at, al, ab, ar = meta.active_area
    hh, ww = ab - at, ar - al
    y = meta.origin[0] + row - at
    x = meta.origin[1] + col - al
    g = 1.0
    for op in meta.opcode_list2:
        gm = op.parsed
        if op.id != 9 or gm.plane != 0:
            continue
        if not (gm.top <= y < gm.bottom and gm.left <= x < gm.right):
            continue
        if (y - gm.top) % gm.row_pitch or (x - gm.left) % gm.col_pitch:
            continue
        pv, ph, _ = gm.gains.shape
        i1, i2, fy = _axis(y, hh, gm.map_origin_v, gm.map_spacing_v, pv)
        j1, j2, fx = _axis(x, ww, gm.map_origin_h, gm.map_spacing_h, ph)
        m = gm.gains[:, :, 0].astype(np.float64)
        top = m[i1, j1] * (1 - fx) + m[i1, j2] * fx
        bot = m[i2, j1] * (1 - fx) + m[i2, j2] * fx
        g *= top * (1 - fy) + bot * fy
    return g


def _check(frame, out, step=(37, 53)):
    rows = list(range(0, frame.height, step[0])) + [frame.height - 1, frame.height - 2]
    cols = list(range(0, frame.width, step[1])) + [frame.width - 1, frame.width - 2, 1]
    for r in rows:
        for c in cols:
            want = reference_gain(frame.meta, r, c)
            got = out.data[r, c] / frame.data[r, c]
            assert abs(got / want - 1) < 1e-6, (r, c, got, want)


@pytest.mark.shared_data
def test_gopro_hero7_full_frame():
    meta = read_dng_meta(shared_path("dng/gopro_hero7_iso252.dng"))
    h, w = meta.extra["image_size"]
    frame = RawFrame(np.full((h, w), 0.25, np.float32), meta, kind="raw")
    out = LensShading()(frame)
    assert out.data.dtype == np.float32 and out.kind == "raw"
    _check(frame, out, step=(97, 131))
    # the four phases are all corrected: corners brighter than the centre in every phase
    for dy in (0, 1):
        for dx in (0, 1):
            ph = out.data[dy::2, dx::2]
            assert ph[0, 0] > 1.2 * ph[h // 4, w // 4]


@pytest.mark.shared_data
def test_gopro_hero6_cropped_at_odd_origin():
    meta = read_dng_meta(shared_path("dng/gopro_hero6_iso100.dng"))
    frame = RawFrame(np.full((3000, 4000), 0.5, np.float32), meta, kind="raw")
    from simcam.stages.raw import Crop

    crop = Crop(region="explicit", rect=(2801, 3, 3000, 301), phase="update")(frame)
    assert crop.meta.origin == (2801, 3)
    out = LensShading()(crop)
    _check(crop, out, step=(7, 11))
    # the crop sees exactly the gains of the full frame at the same positions
    full = gain_field(meta, (3000, 4000))
    np.testing.assert_allclose(out.data / crop.data, full[2801:, 3:301], rtol=1e-6)


@pytest.mark.parametrize("origin", [(0, 0), (3, 5)])
def test_synthetic_maps_with_active_area_offset(origin):
    h, w = 40, 52
    meta = synthetic_meta("GRBG", active_area=(2, 4, h, w),
                          opcode_list2=radial_gain_maps(h - 2, w - 4, points=(4, 6), strength=0.8))
    data = np.random.default_rng(0).uniform(0.1, 0.9, (h, w)).astype(np.float32)
    frame = RawFrame(data, meta, kind="raw")
    if origin != (0, 0):
        frame = RawFrame(data[origin[0]:, origin[1]:], meta.replace(origin=origin), kind="raw")
    out = LensShading()(frame)
    _check(frame, out, step=(1, 1))
    # masked rows/cols (outside the active area) are untouched
    if origin == (0, 0):
        np.testing.assert_array_equal(out.data[:2], data[:2])
        np.testing.assert_array_equal(out.data[:, :4], data[:, :4])


def test_strength_blends_and_no_maps_pass_through():
    h, w = 24, 28
    meta = synthetic_meta("RGGB", active_area=(0, 0, h, w), opcode_list2=radial_gain_maps(h, w))
    frame = RawFrame(np.full((h, w), 0.5, np.float32), meta, kind="raw")
    g = LensShading()(frame).data / 0.5
    half = LensShading(strength=0.5)(frame).data / 0.5
    np.testing.assert_allclose(half, 1 + 0.5 * (g - 1), rtol=1e-6)
    np.testing.assert_array_equal(LensShading(strength=0.0)(frame).data, frame.data)
    plain = RawFrame(frame.data, meta.replace(opcode_list2=[]), kind="raw")
    np.testing.assert_array_equal(LensShading()(plain).data, plain.data)


def test_stage_contract():
    assert get_stage_class("lens_shading") is LensShading
    meta = synthetic_meta("RGGB")
    with pytest.raises(StageError, match="lens_shading"):
        LensShading()(RawFrame(np.zeros((4, 4)), meta, kind="raw_dn"))
    with pytest.raises(Exception):
        LensShading(strength=1.5)
    assert LensShading(strength=0.5).to_node() == {"type": "lens_shading", "strength": 0.5}


def test_cropped_frame_without_geometry_raises():
    from simcam.errors import MetadataError

    meta = synthetic_meta("RGGB", opcode_list2=radial_gain_maps(16, 16)).replace(origin=(2, 2))
    with pytest.raises(MetadataError, match="active_area"):
        LensShading()(RawFrame(np.ones((8, 8)), meta, kind="raw"))


def test_sidd_mode_matches_opencv_style_resize_reference():
    """mode: sidd = first GainMap, resized like cv2.INTER_LINEAR (skimage order-1 resize is
    the independent reference: same half-pixel mapping, edge clamp), one gain per Bayer cell."""
    skt = pytest.importorskip("skimage.transform")
    from simcam.stages.lens_shading import LensShading

    h, w = 40, 60
    meta = synthetic_meta("RGGB", active_area=(0, 0, h, w), opcode_list2=radial_gain_maps(h, w, points=(5, 7)))
    frame = RawFrame(np.full((h, w), 0.5, np.float32), meta, kind="raw")
    out = LensShading(mode="sidd")(frame).data
    grid = meta.gain_maps(2)[0].gains[:, :, 0].astype(np.float64)
    ref = skt.resize(grid, (h // 2, w // 2), order=1, mode="edge", anti_aliasing=False)
    for dy in (0, 1):
        for dx in (0, 1):
            np.testing.assert_allclose(out[dy::2, dx::2], 0.5 * ref, rtol=2e-6)
