"""write_dng: rawpy (LibRaw) reads identical pixels and CFA; read_dng reads identical metadata."""

from __future__ import annotations

import os

import numpy as np
import pytest
import rawpy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from shared_data import shared_path
from dng_fixtures import file_sha256, make_dng  # noqa: F401  (fixture)
from simcam.cfa import BAYER_PATTERNS
from simcam.errors import DngError
from simcam.frame import CameraMeta, RawFrame
from simcam.io.dng import read_dng, read_dng_meta
from simcam.io.dng_write import to_rational, write_dng
from simcam.io.opcodes import parse_opcode_list, serialise_opcode_list
from simcam.io.sample_dng import radial_gain_maps, synthetic_meta
from simcam.stages.raw import Normalize


def _rawpy(path):
    with rawpy.imread(str(path)) as r:
        desc = r.color_desc.decode()
        return r.raw_image.copy(), "".join(desc[c] for c in r.raw_colors[:2, :2].ravel())


def full_meta(cfa="RGGB", h=40, w=48) -> CameraMeta:
    """Every field the DNG can hold, with rational-friendly values."""
    return synthetic_meta(
        cfa, black=0.0, white=4000.0,
        make="Acme", model="Cam 1", unique_camera_model="Acme Cam 1",
        black_level=np.array([[60.0, 61.5], [62.0, 63.25]]),
        black_level_delta_h=np.linspace(-1, 1, w - 4).round(3),
        black_level_delta_v=np.linspace(0, 2, h - 2).round(3),
        linearization_table=None,
        as_shot_white_xy=np.array([0.3457, 0.3585]),
        camera_calibration1=np.eye(3) * 1.0125, camera_calibration2=np.eye(3),
        forward_matrix1=np.array([[0.7461, -0.0195, 0.2373], [0.2832, 0.7031, 0.0137], [0.0254, -0.4561, 1.2559]]),
        forward_matrix2=np.array([[0.6299, 0.0186, 0.3154], [0.1650, 0.7764, 0.0586], [0.0186, -0.8496, 1.6563]]),
        analog_balance=np.array([1.0, 1.0, 0.975]),
        baseline_exposure=-0.25,
        noise_profile=np.array([[3.9362526149488986e-4, 1.2297640239467e-7], [2e-4, 1e-7], [1.5e-4, 3e-8]]),
        iso=252.0, exposure_time_s=1 / 576, orientation=6,
        active_area=(2, 4, h, w), default_crop_origin=(2.0, 1.0), default_crop_size=(40.0, 36.0),
        opcode_list2=radial_gain_maps(h - 2, w - 4),
    )


@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_rawpy_reads_identical_pixels_and_cfa(tmp_path, cfa):
    rng = np.random.default_rng(1)
    data = rng.integers(0, 4096, (24, 30)).astype(np.float32)
    path = write_dng(tmp_path / f"{cfa}.dng", data, synthetic_meta(cfa, white=4095.0))
    raw, rawpy_cfa = _rawpy(path)
    np.testing.assert_array_equal(raw, data)
    assert rawpy_cfa == cfa
    frame = read_dng(path)
    np.testing.assert_array_equal(frame.data, data)
    assert frame.meta.cfa == cfa


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_full_metadata_round_trip(tmp_path, cfa):
    meta = full_meta(cfa)
    data = np.random.default_rng(2).integers(0, 4001, (40, 48))
    path = write_dng(tmp_path / "full.dng", data, meta)
    back = read_dng(path)
    assert meta.differences(back.meta) == []
    np.testing.assert_array_equal(back.data, data)
    raw, rawpy_cfa = _rawpy(path)
    np.testing.assert_array_equal(raw, data)
    assert rawpy_cfa == cfa  # CFAPattern written relative to the (even) active-area corner


def test_odd_active_area_keeps_the_cfa_of_stored_pixel_00(tmp_path):
    # CFAPattern is anchored at the ActiveArea top-left: with an odd corner the tag
    # differs from meta.cfa, and LibRaw must still agree on the colour of pixel (0, 0).
    meta = synthetic_meta("GRBG", white=4095.0, active_area=(1, 3, 31, 39))
    data = np.random.default_rng(3).integers(0, 4096, (32, 40))
    path = write_dng(tmp_path / "odd.dng", data, meta)
    back = read_dng_meta(path)
    assert back.cfa == "GRBG" and back.extra["cfa_pattern_tag"] == "GBRG"
    assert _rawpy(path)[1] == "GRBG"


def test_normalised_frame_is_denormalised(tmp_path):
    meta = full_meta("BGGR")
    data = np.random.default_rng(4).integers(70, 4001, (40, 48)).astype(np.float32)
    raw = Normalize()(RawFrame(data, meta, kind="raw_dn"))
    path = write_dng(tmp_path / "raw.dng", raw)
    np.testing.assert_array_equal(read_dng(path).data, data)


def test_linearization_table_round_trip(tmp_path):
    # LibRaw applies the table while decoding; read_dng returns the stored codes
    table = (np.arange(1024) * 3 + (np.arange(1024) ** 2) // 512).astype(np.float64)
    meta = synthetic_meta("RGGB", white=float(table[-1]), linearization_table=table)
    data = np.random.default_rng(5).integers(0, 1024, (24, 24))
    path = write_dng(tmp_path / "lin.dng", data, meta)
    raw, _ = _rawpy(path)
    np.testing.assert_array_equal(raw, table[data])
    back = read_dng(path)
    np.testing.assert_array_equal(back.data, data)
    assert meta.differences(back.meta) == []


def test_cropped_frame_translates_active_area(tmp_path):
    meta = full_meta("RGGB")
    data = np.random.default_rng(6).integers(0, 4001, (40, 48)).astype(np.float32)
    from simcam.stages.raw import Crop

    cropped = Crop()(RawFrame(data, meta, kind="raw_dn"))
    assert cropped.meta.origin == (2, 4)
    back = read_dng(write_dng(tmp_path / "crop.dng", cropped))
    assert back.meta.active_area == (0, 0, 38, 44)
    assert back.meta.differences(meta) == ["active_area"]
    np.testing.assert_array_equal(back.data, data[2:, 4:])
    inner = cropped.evolve(meta=cropped.meta.replace(origin=(4, 6)))
    with pytest.raises(DngError, match="inside the active area"):
        write_dng(tmp_path / "inner.dng", inner)


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["gopro_hero7_iso252.dng", "canon_550d_colorchecker.dng"])
def test_real_file_round_trip(tmp_path, name):
    src = shared_path(f"dng/{name}")
    frame = read_dng(src)
    out = write_dng(tmp_path / name, frame)
    back = read_dng(out)
    assert frame.meta.differences(back.meta) == []
    np.testing.assert_array_equal(back.data, frame.data)
    for k in (1, 2, 3):
        ops = getattr(back.meta, f"opcode_list{k}")
        assert serialise_opcode_list(ops) == serialise_opcode_list(getattr(frame.meta, f"opcode_list{k}"))


def test_refuses_to_overwrite_input_and_leaves_no_temp_file(make_dng, tmp_path):  # noqa: F811
    src = make_dng("in.dng")
    before = file_sha256(src)
    frame = read_dng(src)
    with pytest.raises(DngError, match="refusing to overwrite"):
        write_dng(src, frame)
    with pytest.raises(DngError, match="refusing to overwrite"):
        write_dng(src, frame.data, frame.meta.replace(source=""), protect=(src,))
    assert file_sha256(src) == before
    assert sorted(os.listdir(tmp_path)) == ["in.dng"]


def test_writer_input_errors(tmp_path):
    meta = synthetic_meta("RGGB")
    with pytest.raises(DngError, match="NaN"):
        write_dng(tmp_path / "a.dng", np.full((8, 8), np.nan), meta)
    with pytest.raises(DngError, match="clip=False"):
        write_dng(tmp_path / "a.dng", np.full((8, 8), 70000.0), meta, clip=False)
    with pytest.raises(DngError, match="meta is required"):
        write_dng(tmp_path / "a.dng", np.zeros((8, 8)))
    with pytest.raises(DngError, match="cfa is None"):
        write_dng(tmp_path / "a.dng", np.zeros((8, 8)), meta.replace(cfa=None))
    with pytest.raises(DngError, match="kind"):
        write_dng(tmp_path / "a.dng", RawFrame(np.zeros((8, 8, 3)), meta, kind="camera_rgb"))
    with pytest.raises(DngError, match="does not exist"):
        write_dng(tmp_path / "nope" / "a.dng", np.zeros((8, 8)), meta)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("x", [1 / 3, 0.1, 1.8331, -0.8166, 1 / 576, 2056.0, 0.0, 1e-9, 16383 / 256])
def test_rationals_divide_back_exactly(x):
    n, d = to_rational(x, signed=True)
    assert n / d == x and abs(n) < 2 ** 31 and 0 < d < 2 ** 31


@pytest.mark.parametrize("x", [3.9362526149488986e-4, np.pi, -np.e * 100])
def test_irrational_floats_come_back_close(x):
    n, d = to_rational(x, signed=True)
    assert abs(n / d - x) <= 1e-9 * abs(x)


# ---------------------------------------------------------------------------
# property test: random frames and random tag subsets
# ---------------------------------------------------------------------------
_dec = st.integers(-20000, 20000).map(lambda k: k / 10000)
_pos = st.integers(1, 40000).map(lambda k: k / 10000)


@st.composite
def frames(draw):
    h = 2 * draw(st.integers(4, 32))
    w = 2 * draw(st.integers(4, 32))
    cfa = draw(st.sampled_from(BAYER_PATTERNS))
    white = float(draw(st.integers(255, 65535)))
    fields = {}
    opt = {
        "color_matrix1": st.lists(_dec, min_size=9, max_size=9).map(lambda v: np.array(v).reshape(3, 3)),
        "color_matrix2": st.lists(_dec, min_size=9, max_size=9).map(lambda v: np.array(v).reshape(3, 3)),
        "forward_matrix1": st.lists(_dec, min_size=9, max_size=9).map(lambda v: np.array(v).reshape(3, 3)),
        "camera_calibration1": st.lists(_pos, min_size=9, max_size=9).map(lambda v: np.array(v).reshape(3, 3)),
        "as_shot_neutral": st.lists(_pos, min_size=3, max_size=3).map(np.array),
        "analog_balance": st.lists(_pos, min_size=3, max_size=3).map(np.array),
        "noise_profile": st.lists(st.floats(1e-9, 1e-2), min_size=2, max_size=2).map(lambda v: np.array([v])),
        "calibration_illuminant1": st.integers(0, 24),
        "baseline_exposure": _dec,
        "iso": st.integers(25, 25600).map(float),
        "exposure_time_s": st.integers(1, 8000).map(lambda k: 1 / k),
        "orientation": st.integers(1, 8),
        "black_level": st.lists(st.integers(0, 200), min_size=4, max_size=4).map(
            lambda v: np.array(v, dtype=float).reshape(2, 2)),
    }
    for name in draw(st.sets(st.sampled_from(sorted(opt)))):
        fields[name] = draw(opt[name])
    if draw(st.booleans()):
        t, l = 2 * draw(st.integers(0, 1)), 2 * draw(st.integers(0, 1))
        fields["active_area"] = (t, l, h, w)
        if draw(st.booleans()):
            fields["opcode_list2"] = radial_gain_maps(h - t, w - l, points=(3, 4))
        if draw(st.booleans()):
            fields["default_crop_origin"] = (1.0, 1.0)
            fields["default_crop_size"] = (float(w - l - 2), float(h - t - 2))
    meta = synthetic_meta(cfa, black=0.0, white=white, minimal=True, **fields)
    seed = draw(st.integers(0, 2 ** 16))
    data = np.random.default_rng(seed).integers(0, int(white) + 1, (h, w))
    return data, meta


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frames())
def test_random_round_trip(tmp_path, sample):
    data, meta = sample
    path = write_dng(tmp_path / "r.dng", data, meta)
    back = read_dng(path)
    assert meta.differences(back.meta) == []
    np.testing.assert_array_equal(back.data, data)
    t, l, b, r = meta.active_area or (0, 0) + data.shape
    if min(b - t, r - l) >= 22:  # LibRaw refuses smaller (active) images
        raw, cfa = _rawpy(path)
        np.testing.assert_array_equal(raw, data)
        assert cfa == meta.cfa
    for k in (2,):
        ops = getattr(back.meta, f"opcode_list{k}")
        assert serialise_opcode_list(parse_opcode_list(serialise_opcode_list(ops))) == serialise_opcode_list(ops)
