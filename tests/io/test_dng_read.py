"""read_dng / read_dng_meta on real DNGs, checked against rawpy (LibRaw) and tifffile's raw tags."""

from __future__ import annotations

import numpy as np
import pytest
import rawpy
import tifffile

from shared_data import shared_path
from dng_fixtures import file_sha256
from simcam.io.dng import read_dng, read_dng_meta

pytestmark = pytest.mark.shared_data

READABLE = ["gopro_hero7_iso252.dng", "gopro_hero6_iso100.dng", "gopro_fusion_front_iso100.dng",
            "canon_550d_colorchecker.dng"]


def _rawpy_reference(path):
    with rawpy.imread(str(path)) as r:
        desc = r.color_desc.decode()
        return dict(
            raw=r.raw_image.copy(),
            # rawpy.raw_colors is relative to the full raw image (rawpy docs)
            cfa="".join(desc[c] for c in r.raw_colors[:2, :2].ravel()),
            colors=r.raw_colors[:2, :2].copy(),
            black=list(r.black_level_per_channel),  # indexes color_desc, not CFA positions
            white=r.white_level,
        )


def _ifd0_numbers(path, code):
    """Tag value from IFD0 as float64; rationals divided (written independently of simcam)."""
    with tifffile.TiffFile(str(path)) as tif:
        tag = tif.pages[0].tags.get(code)
        if tag is None:
            return None
        v = np.atleast_1d(np.asarray(tag.value, dtype=np.float64))
        if tag.dtype in (5, 10):
            num, den = v[0::2], v[1::2]
            # 0/0 (BaselineExposure of the Magic Lantern file) is read as 0
            v = np.divide(num, den, out=np.zeros_like(num), where=(den != 0) | (num != 0))
        return v


@pytest.fixture(scope="module", params=READABLE)
def real(request):
    path = shared_path(f"dng/{request.param}")
    return path, read_dng(path), _rawpy_reference(path)


def test_pixels_equal_rawpy(real):
    path, frame, ref = real
    assert frame.kind == "raw_dn" and frame.data.dtype == np.float32
    assert frame.meta.origin == (0, 0)
    assert frame.data.shape == ref["raw"].shape
    np.testing.assert_array_equal(frame.data, ref["raw"].astype(np.float32))


def test_cfa_black_white_match_rawpy(real):
    path, frame, ref = real
    meta = frame.meta
    assert meta.cfa == ref["cfa"]
    assert meta.white_level == ref["white"]
    bl = np.asarray(meta.black_level)
    top, left = meta.active_area[:2] if meta.active_area else (0, 0)
    for i in range(2):
        for j in range(2):
            channel = ref["colors"][i, j]
            # BlackLevel is anchored at the active area's top-left
            assert bl[(i - top) % bl.shape[0], (j - left) % bl.shape[1]] == ref["black"][channel]


MATRIX_TAGS = {50721: "color_matrix1", 50722: "color_matrix2", 50723: "camera_calibration1",
               50724: "camera_calibration2", 50964: "forward_matrix1", 50965: "forward_matrix2"}
VECTOR_TAGS = {50727: "analog_balance", 50728: "as_shot_neutral", 50729: "as_shot_white_xy"}


def test_matrices_and_vectors_match_raw_tags(real):
    path, frame, _ = real
    meta = frame.meta
    for code, field in MATRIX_TAGS.items():
        want = _ifd0_numbers(path, code)
        got = getattr(meta, field)
        if want is None:
            assert got is None, field
        else:
            np.testing.assert_array_equal(got, want.reshape(3, 3), err_msg=field)
    for code, field in VECTOR_TAGS.items():
        want = _ifd0_numbers(path, code)
        got = getattr(meta, field)
        assert (got is None) == (want is None), field
        if want is not None:
            np.testing.assert_array_equal(got, want, err_msg=field)
    np.testing.assert_array_equal(meta.baseline_exposure, _ifd0_numbers(path, 50730)[0])
    ill1 = _ifd0_numbers(path, 50778)
    assert meta.calibration_illuminant1 == (None if ill1 is None else int(ill1[0]))
    npf = _ifd0_numbers(path, 51041)
    if npf is None:
        assert meta.noise_profile is None
    else:
        np.testing.assert_array_equal(meta.noise_profile, npf.reshape(-1, 2))


def test_geometry_and_exif(real):
    path, frame, _ = real
    meta = frame.meta
    with tifffile.TiffFile(str(path)) as tif:
        p = tif.pages[0]
        exif = p.tags["ExifTag"].value
        assert meta.orientation == int(p.tags[274].value)
        assert meta.make == p.tags[271].value and meta.model == p.tags[272].value
        assert meta.unique_camera_model == p.tags[50708].value
    assert tuple(meta.active_area) == tuple(int(x) for x in _ifd0_numbers(path, 50829))
    np.testing.assert_array_equal(meta.default_crop_origin, _ifd0_numbers(path, 50719))
    np.testing.assert_array_equal(meta.default_crop_size, _ifd0_numbers(path, 50720))
    iso = exif["ISOSpeedRatings"]
    assert meta.iso == (float(iso) if iso > 0 else None)  # EXIF 0 = unknown
    num, den = exif["ExposureTime"]
    assert meta.exposure_time_s == (num / den if num > 0 else None)


def test_known_values():
    hero7 = read_dng_meta(shared_path("dng/gopro_hero7_iso252.dng"))
    assert (hero7.iso, hero7.cfa, hero7.white_level, hero7.orientation) == (252.0, "RGGB", 16383.0, 2)
    assert hero7.calibration_illuminant1 == 3 and hero7.calibration_illuminant2 == 23
    assert hero7.noise_profile.shape == (1, 2)
    canon = read_dng_meta(shared_path("dng/canon_550d_colorchecker.dng"))
    assert canon.active_area == (26, 152, 1182, 1886)
    assert canon.black_level.tolist() == [[2056.0]] and canon.white_level == 15000.0
    assert canon.color_matrix2 is None and canon.noise_profile is None
    assert canon.default_crop_size == (1734.0, 1156.0)
    fusion = read_dng_meta(shared_path("dng/gopro_fusion_front_iso100.dng"))
    assert [op.name for op in fusion.opcode_list3] == ["WarpRectilinear"] and not fusion.opcode_list2


def test_meta_only_equals_full_read_and_file_untouched():
    path = shared_path("dng/canon_550d_colorchecker.dng")
    before = file_sha256(path)
    assert read_dng_meta(path).differences(read_dng(path).meta) == []
    assert file_sha256(path) == before


def test_cfa_plane_color_is_respected(tmp_path):
    """CFAPattern indexes CFAPlaneColor: planes (B, G, R) turn a written RGGB into BGGR (LibRaw agrees)."""
    from simcam.io.sample_dng import make_test_dng

    path = make_test_dng(tmp_path / "a.dng", 32, 32, "RGGB")
    raw = bytearray(path.read_bytes())
    with tifffile.TiffFile(str(path)) as tif:
        off = tif.pages[0].tags[50710].valueoffset
    raw[off:off + 3] = bytes([2, 1, 0])
    patched = tmp_path / "b.dng"
    patched.write_bytes(bytes(raw))
    assert read_dng_meta(patched).cfa == "BGGR"
    assert _rawpy_reference(patched)["cfa"] == "BGGR"


def test_iso_in_ifd0_with_several_values(tmp_path):
    from simcam.io.sample_dng import synthetic_meta

    path = tmp_path / "iso.dng"
    tifffile.imwrite(path, np.zeros((24, 24), np.uint16), photometric=32803, extratags=[
        (50706, 1, 4, b"\x01\x04\x00\x00", True), (33421, 3, 2, (2, 2), True), (33422, 1, 4, b"\x01\x00\x02\x01", True),
        (34855, 3, 2, (400, 400), True), (33434, 5, 1, (1, 50), True)])
    meta = read_dng_meta(path)
    assert meta.iso == 400.0 and meta.exposure_time_s == 0.02 and meta.cfa == "GRBG"
    assert meta.white_level == 65535.0 and meta.active_area is None
    assert synthetic_meta("GRBG").cfa == meta.cfa
