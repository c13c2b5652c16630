"""Reading DNG camera profiles: the shared .dcp files, synthetic ones, malformed bytes, embedded tags."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from dcp_fixtures import (
    ASCII,
    FLOAT,
    LONG,
    SHORT,
    SRATIONAL,
    TAG,
    add_ifd0_tags,
    dcp_bytes,
    identity_table,
    profile_tags,
    write_dcp,
)
from shared_data import shared_path

from simcam.errors import DngError
from simcam.io.dcp import CameraProfile, parse_dcp, read_dcp
from simcam.io.dng import read_dng_meta
from simcam.io.sample_dng import make_test_dng

# -- the shared files ------------------------------------------------------------------------------

SHARED = {
    # file: (ProfileName, HueSatMap dims, second map, LookTable dims, look encoding, tone points, black render)
    "Canon_EOS_550D": ("EOS 550D - 6145", (6, 6, 3), False, None, None, None, 0),
    "LG_Mobile_LG-H815": ("LG Mobile LG-H815", (90, 30, 1), True, (90, 30, 30), 1, 8192, 0),
    "samsung_SM-G930V": ("samsung SM-G930V", (90, 30, 1), True, None, None, 2, 1),
}


@pytest.mark.shared_data
@pytest.mark.parametrize("name", sorted(SHARED))
def test_shared_dcp_files_parse(name):
    import tifffile

    path = shared_path(f"dcp/{name}.dcp")
    prof = read_dcp(path)
    pname, hsm_dims, two, look_dims, look_enc, tone_pts, black = SHARED[name]
    assert prof.name == pname and prof.source == str(path)
    assert prof.hue_sat_map1.dims == hsm_dims and (prof.hue_sat_map2 is not None) == two
    assert (prof.look_table.dims if prof.look_table else None) == look_dims
    if look_enc is not None:
        assert prof.look_table.encoding == look_enc
    assert (None if prof.tone_curve is None else prof.tone_curve.shape[0]) == tone_pts
    assert prof.default_black_render == black and prof.baseline_exposure_offset == 0.0
    assert prof.color_matrix1.shape == (3, 3) and not prof.third_illuminant
    # independent parse: tifffile reads the same IFD (it accepts the 'RC' magic)
    with tifffile.TiffFile(str(path)) as tif:
        tags = tif.pages[0].tags
        cm = np.asarray(tags[TAG["ColorMatrix1"]].value, dtype=float).reshape(-1, 2)
        assert np.allclose(prof.color_matrix1.ravel(), cm[:, 0] / cm[:, 1], rtol=0, atol=1e-12)
        assert np.array_equal(prof.hue_sat_map1.data.ravel(), np.asarray(tags[TAG["ProfileHueSatMapData1"]].value, np.float32))
        if prof.look_table is not None:
            assert np.array_equal(prof.look_table.data.ravel(), np.asarray(tags[TAG["ProfileLookTableData"]].value, np.float32))
    # storage order: value outer, hue middle, saturation inner; zero-saturation entries keep the value
    assert np.allclose(prof.hue_sat_map1.data[:, :, 0, 2], 1.0)
    if prof.tone_curve is not None:
        assert tuple(prof.tone_curve[0]) == (0.0, 0.0) and tuple(prof.tone_curve[-1]) == (1.0, 1.0)
    assert "CameraProfile(" in str(prof) and pname in str(prof)


# -- synthetic files ---------------------------------------------------------------------------------

@pytest.mark.parametrize("big_endian", [False, True])
def test_synthetic_dcp_round_trip(tmp_path, big_endian):
    rng = np.random.default_rng(3)
    hsm1 = identity_table(8, 4, 2)
    hsm1[..., 0] = rng.uniform(-20, 20, hsm1.shape[:3])
    hsm2 = identity_table(8, 4, 2)
    look = identity_table(6, 3, 5)
    look[..., 1] = rng.uniform(0.8, 1.2, look.shape[:3])
    tone = [[0, 0], [0.25, 0.3], [0.6, 0.75], [1, 1]]
    p = write_dcp(tmp_path / "x.dcp", profile_tags(hsm1=hsm1, hsm2=hsm2, look=look, hsm_encoding=1, look_encoding=1,
                                                    tone=tone, baseline_offset=-0.5, black_render=1),
                  big_endian=big_endian)
    prof = read_dcp(p)
    assert prof.hue_sat_map1.dims == (8, 4, 2) and prof.hue_sat_map1.encoding == 1
    assert np.array_equal(prof.hue_sat_map1.data, hsm1) and np.array_equal(prof.hue_sat_map2.data, hsm2)
    assert np.array_equal(prof.look_table.data, look) and prof.look_table.encoding == 1
    assert np.allclose(prof.tone_curve, tone) and prof.baseline_exposure_offset == -0.5
    assert prof.default_black_render == 1 and prof.calibration_illuminant1 == 17 and prof.calibration_illuminant2 == 21
    assert prof.forward_matrix1 is not None and prof.name == "test profile"
    assert not prof.hue_sat_map1.data.flags.writeable  # immutable, shared by metadata copies
    import copy

    assert copy.deepcopy(prof) is prof


def test_read_dcp_missing_and_directory(tmp_path):
    with pytest.raises(DngError, match="no such file"):
        read_dcp(tmp_path / "nope.dcp")
    with pytest.raises(DngError, match="is a directory"):
        read_dcp(tmp_path)


def _good():
    return profile_tags(hsm1=identity_table(6, 3, 1))


def _replace(tags, code, typ, values):
    return [t for t in tags if t[0] != code] + [(code, typ, values)]


def _drop(tags, code):
    return [t for t in tags if t[0] != code]


HSM_DIMS, HSM1 = TAG["ProfileHueSatMapDims"], TAG["ProfileHueSatMapData1"]
TONE = TAG["ProfileToneCurve"]

MALFORMED_TAGS = {
    "ColorMatrix1 count": (lambda t: _replace(t, TAG["ColorMatrix1"], SRATIONAL, [1, 0, 0, 0, 1, 0]),
                           "ColorMatrix1: 6 values"),
    "ColorMatrix1 missing": (lambda t: _drop(t, TAG["ColorMatrix1"]), "ColorMatrix1: missing"),
    "ColorMatrix1 as text": (lambda t: _replace(t, TAG["ColorMatrix1"], ASCII, "identity"),
                             "ColorMatrix1: type ASCII"),
    "dims as float": (lambda t: _replace(t, HSM_DIMS, FLOAT, [6, 3, 1]), "ProfileHueSatMapDims: type FLOAT"),
    "dims count": (lambda t: _replace(t, HSM_DIMS, LONG, [6, 3]), "ProfileHueSatMapDims: 2 values"),
    "one saturation division": (lambda t: _replace(_replace(t, HSM_DIMS, LONG, [6, 1, 1]), HSM1, FLOAT,
                                                   identity_table(6, 1, 1).ravel()), "saturation divisions >= 2"),
    "data count": (lambda t: _replace(t, HSM1, FLOAT, np.ones(6 * 3 * 3 - 3)), "ProfileHueSatMapData1: 51 values"),
    "data without dims": (lambda t: _drop(t, HSM_DIMS), "ProfileHueSatMapData1: present without ProfileHueSatMapDims"),
    "dims without data": (lambda t: _drop(t, HSM1), "ProfileHueSatMapData1: missing although"),
    "second map without first": (lambda t: _replace(_drop(t, HSM1), TAG["ProfileHueSatMapData2"], FLOAT,
                                                    identity_table(6, 3, 1).ravel()), "ProfileHueSatMapData1: missing"),
    "NaN in data": (lambda t: _replace(t, HSM1, FLOAT, np.where(np.arange(54) == 7, np.nan, identity_table(6, 3, 1).ravel())),
                    "ProfileHueSatMapData1: non-finite"),
    "negative scale": (lambda t: _replace(t, HSM1, FLOAT, identity_table(6, 3, 1).ravel() * np.tile([1, -1, 1], 18)),
                       "negative saturation or value scale"),
    "encoding 2": (lambda t: t + [(TAG["ProfileHueSatMapEncoding"], LONG, 2)],
                   "ProfileHueSatMapEncoding: 2; expected one of 0, 1"),
    "black render 3": (lambda t: t + [(TAG["DefaultBlackRender"], LONG, 3)], "DefaultBlackRender: 3"),
    "tone odd": (lambda t: t + [(TONE, FLOAT, [0, 0, 0.5, 0.5, 1])], "ProfileToneCurve: 5 values"),
    "tone decreasing": (lambda t: t + [(TONE, FLOAT, [0, 0, 0.6, 0.5, 0.4, 0.7, 1, 1])], "not strictly increasing"),
    "tone not to (1, 1)": (lambda t: t + [(TONE, FLOAT, [0, 0, 0.5, 0.6, 1, 0.9])], "expected (0, 0) to (1, 1)"),
    "tone outside": (lambda t: t + [(TONE, FLOAT, [0, 0, 0.5, 1.5, 1, 1])], "outside [0, 1]"),
    "illuminant as float": (lambda t: _replace(t, TAG["CalibrationIlluminant1"], FLOAT, 17.0),
                            "CalibrationIlluminant1: type FLOAT"),
    "huge table": (lambda t: _replace(t, HSM_DIMS, LONG, [4096, 4096, 2]), "entries; expected at most"),
    "offset": (lambda t: t + [(TAG["BaselineExposureOffset"], SRATIONAL, 100.0)], "BaselineExposureOffset: 100 EV"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED_TAGS))
def test_malformed_tags_are_one_line_errors(case):
    mutate, message = MALFORMED_TAGS[case]
    data = dcp_bytes(mutate(_good()))
    with pytest.raises(DngError) as err:
        parse_dcp(data, "bad.dcp")
    text = str(err.value)
    assert text.startswith("bad.dcp: ") and "\n" not in text
    assert message in text, text


def _set_entry(data: bytes, code: int, *, typ=None, count=None, field=None) -> bytes:
    """Patch one IFD entry of a little-endian dcp (IFD at byte 8)."""
    b = bytearray(data)
    (n,) = struct.unpack("<H", b[8:10])
    for k in range(n):
        off = 10 + 12 * k
        c, t, cnt = struct.unpack("<HHI", b[off:off + 8])
        if c == code:
            b[off:off + 8] = struct.pack("<HHI", c, t if typ is None else typ, cnt if count is None else count)
            if field is not None:
                b[off + 8:off + 12] = field
            return bytes(b)
    raise AssertionError(code)


def test_malformed_bytes_are_one_line_errors():
    good = dcp_bytes(_good())
    parse_dcp(good)  # the baseline parses
    cases = {
        "empty": (b"", "header: 0 bytes"),
        "tiff magic": (b"II*\0" + good[4:], "a TIFF/DNG file, not a camera profile"),
        "other magic": (b"XXRC" + good[4:], "magic b'XXRC'"),
        "truncated header": (good[:6], "header: 6 bytes"),
        "IFD outside": (good[:4] + struct.pack("<I", len(good) + 10) + good[8:], "IFD offset"),
        "IFD truncated": (good[:40], "do not fit in the file"),
        "values truncated": (good[:-20], "run past the end of the file"),
        "count too large": (_set_entry(good, HSM1, count=10 ** 8), "run past the end of the file"),
        "unknown type": (_set_entry(good, HSM1, typ=99), "unknown TIFF field type 99"),
        "count 0": (_set_entry(good, HSM1, count=0), "count 0"),
        "zero entries": (good[:8] + struct.pack("<H", 0) + good[10:], "0 entries"),
        "zero denominator": (_zero_denominator(good), "zero denominator"),
    }
    for name, (data, message) in cases.items():
        with pytest.raises(DngError) as err:
            parse_dcp(data, "bad.dcp")
        text = str(err.value)
        assert text.startswith("bad.dcp: ") and "\n" not in text, name
        assert message in text, (name, text)


def _zero_denominator(good: bytes) -> bytes:
    b = bytearray(good)
    (n,) = struct.unpack("<H", b[8:10])
    for k in range(n):
        off = 10 + 12 * k
        c, t, cnt = struct.unpack("<HHI", b[off:off + 8])
        if c == TAG["ColorMatrix1"]:
            (vo,) = struct.unpack("<I", b[off + 8:off + 12])
            b[vo + 4:vo + 8] = struct.pack("<i", 0)  # first denominator; numerator is non-zero
            return bytes(b)
    raise AssertionError


def test_duplicate_tag_is_an_error():
    data = dcp_bytes(_good() + [(TAG["ProfileName"], ASCII, "again")])
    with pytest.raises(DngError, match="dup.dcp: ProfileName: appears twice"):
        parse_dcp(data, "dup.dcp")


def test_unknown_tags_are_ignored():
    prof = parse_dcp(dcp_bytes(_good() + [(40000, SHORT, [1, 2, 3]), (40001, LONG, 7)]))
    assert isinstance(prof, CameraProfile)


# -- profile tags embedded in a DNG -----------------------------------------------------------------------

def test_embedded_profile_tags_are_read(tmp_path):
    path = make_test_dng(tmp_path / "p.dng", 32, 32, "RGGB")
    assert "camera_profile" not in read_dng_meta(path).extra  # no profile tags: nothing recorded
    hsm = identity_table(6, 3, 1)
    hsm[..., 0] = 5.0
    look = identity_table(4, 2, 3)
    add_ifd0_tags(path, [(TAG["ProfileHueSatMapDims"], LONG, [6, 3, 1]), (TAG["ProfileHueSatMapData1"], FLOAT, hsm.ravel()),
                         (TAG["ProfileLookTableDims"], LONG, [4, 2, 3]), (TAG["ProfileLookTableData"], FLOAT, look.ravel()),
                         (TAG["ProfileLookTableEncoding"], LONG, 1), (TAG["BaselineExposureOffset"], SRATIONAL, 0.25),
                         (TAG["DefaultBlackRender"], LONG, 1), (TAG["ProfileToneCurve"], FLOAT, [0, 0, 0.5, 0.6, 1, 1])])
    meta = read_dng_meta(path)
    prof = meta.extra["camera_profile"]
    assert isinstance(prof, CameraProfile) and prof.source == str(path)
    assert np.array_equal(prof.hue_sat_map1.data, hsm) and prof.look_table.encoding == 1
    assert prof.baseline_exposure_offset == 0.25 and prof.default_black_render == 1 and prof.tone_curve.shape == (3, 2)
    assert meta.copy().extra["camera_profile"] is prof  # shared, not copied
    import json

    text = json.dumps(meta.to_dict(), default=str)  # `simcam info --json`: summarised, not 54 numbers
    assert "CameraProfile(" in text and "look_table" in text


def test_embedded_profile_malformed_is_a_dng_error(tmp_path):
    path = make_test_dng(tmp_path / "p.dng", 32, 32, "RGGB")
    add_ifd0_tags(path, [(TAG["ProfileHueSatMapDims"], LONG, [6, 3, 1]), (TAG["ProfileHueSatMapData1"], FLOAT, np.ones(10))])
    with pytest.raises(DngError) as err:
        read_dng_meta(path)
    assert str(err.value).startswith(f"{path}: ProfileHueSatMapData1: 10 values")


@pytest.mark.shared_data
def test_shared_dngs_have_no_embedded_tables():
    for name in ("canon_550d_colorchecker", "gopro_hero7_iso252"):
        meta = read_dng_meta(shared_path(f"dng/{name}.dng"))
        assert "camera_profile" not in meta.extra
