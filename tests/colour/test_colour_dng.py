"""DNG camera colour (simcam.colour.dng) against colour-science / colour-hdri.

Reference: colour-hdri's implementation of DNG 1.6 chapter 6
(``colour_hdri.models.dng``) and colour-science's Robertson (1968) CCT.
Real tags are read here directly (tifffile / scipy.io), independent of simcam's reader.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from shared_data import shared_path
from simcam.colour import dng as D
from simcam.errors import MetadataError

H = pytest.importorskip("colour_hdri.models.dng")
colour = pytest.importorskip("colour")

DNGS = ["gopro_hero7_iso252", "gopro_hero6_iso100", "gopro_fusion_front_iso100", "canon_550d_colorchecker"]
TAGS = ["ColorMatrix1", "ColorMatrix2", "CameraCalibration1", "CameraCalibration2", "ForwardMatrix1",
        "ForwardMatrix2", "AnalogBalance", "AsShotNeutral", "AsShotWhiteXY", "CalibrationIlluminant1",
        "CalibrationIlluminant2"]


def _rationals(v):
    v = np.asarray(v, dtype=np.float64).ravel()
    return v[0::2] / v[1::2]


def tags_from_dng(name: str) -> dict:
    import tifffile

    path = shared_path(f"dng/{name}.dng")
    with tifffile.TiffFile(str(path)) as tif:
        page = tif.pages[0]
        out = {}
        for tag in TAGS:
            if tag in page.tags:
                v = page.tags[tag].value
                out[tag] = int(v) if tag.startswith("Calibration") else _rationals(v)
    out["source"] = str(path)
    return out


def tags_from_sidd() -> dict:
    import scipy.io

    path = shared_path("sidd/0001_METADATA_RAW_010.MAT")
    m = scipy.io.loadmat(str(path))["metadata"][0, 0]
    out = {}
    for tag in TAGS:
        if tag in m.dtype.names and m[tag].size:
            v = np.asarray(m[tag], dtype=np.float64).ravel()
            out[tag] = int(v[0]) if tag.startswith("Calibration") else v
    unknown = {int(np.asarray(r[0]).ravel()[0]): np.asarray(r[2], dtype=np.float64).ravel()
               for r in m["UnknownTags"][:, 0]}
    out["ForwardMatrix1"], out["ForwardMatrix2"] = unknown[50964], unknown[50965]  # DNG tag ids
    out["source"] = str(path)
    return out


def meta_of(t: dict) -> SimpleNamespace:
    mat = lambda k: None if k not in t else np.asarray(t[k]).reshape(3, 3)  # noqa: E731
    return SimpleNamespace(
        color_matrix1=mat("ColorMatrix1"), color_matrix2=mat("ColorMatrix2"),
        camera_calibration1=mat("CameraCalibration1"), camera_calibration2=mat("CameraCalibration2"),
        forward_matrix1=mat("ForwardMatrix1"), forward_matrix2=mat("ForwardMatrix2"),
        analog_balance=t.get("AnalogBalance"), calibration_illuminant1=t.get("CalibrationIlluminant1"),
        calibration_illuminant2=t.get("CalibrationIlluminant2"), source=t["source"])


def hdri_args(t: dict) -> list:
    """colour-hdri's positional arguments. It expects identity for absent matrices and the
    illuminants in ascending CCT (its interpolation clamps to M1 below CCT1), so a profile
    whose CalibrationIlluminant1 is the warmer one is passed with both sets swapped."""
    eye = np.eye(3)
    get = lambda k: eye if k not in t else np.asarray(t[k]).reshape(3, 3)  # noqa: E731
    cct = {c: H_CCT(t.get(f"CalibrationIlluminant{c}")) for c in (1, 2)}
    sets = {c: (get(f"ColorMatrix{c}"), get(f"CameraCalibration{c}"), get(f"ForwardMatrix{c}")) for c in (1, 2)}
    if "ColorMatrix2" not in t or cct[1] is None or cct[2] is None:
        # single-illuminant profile: identity ColorMatrix2 makes colour-hdri use ColorMatrix1;
        # set 2's calibration / forward matrices repeat set 1's so interpolation is a no-op
        cct = {1: 5000.0, 2: 6500.0}
        sets[2] = (eye, sets[1][1], sets[1][2])
    a, b = (1, 2) if cct[1] <= cct[2] else (2, 1)
    ab = np.asarray(t.get("AnalogBalance", np.ones(3)))
    return [cct[a], cct[b], sets[a][0], sets[b][0], sets[a][1], sets[b][1], ab, sets[a][2], sets[b][2]]


def H_CCT(code):
    """CCT of a LightSource code from colour-hdri's DNG SDK tables (None when unknown)."""
    from colour_hdri.models.datasets.dng import CCT_ILLUMINANTS_ADOBEDNG, LIGHT_SOURCE_TAG_TO_DNG_ILLUMINANTS

    name = LIGHT_SOURCE_TAG_TO_DNG_ILLUMINANTS.get(code)
    return None if name is None or name not in CCT_ILLUMINANTS_ADOBEDNG else float(CCT_ILLUMINANTS_ADOBEDNG[name])


def all_tag_sets():
    return [pytest.param(n, id=n) for n in DNGS] + [pytest.param("sidd", id="sidd_0001")]


def load(name):
    return tags_from_sidd() if name == "sidd" else tags_from_dng(name)


# -- illuminants and CCT ------------------------------------------------------------------

def test_illuminant_cct_matches_dng_sdk_table():
    for code in list(range(0, 30)) + [255, 1000]:
        assert D.illuminant_cct(code) == H_CCT(code), code
    assert D.illuminant_cct(None) is None and D.illuminant_xy(0) is None and D.illuminant_xy(255) is None
    # any value may be found in a file: non-integers, text, arrays
    assert D.illuminant_cct(21.5) is None and D.illuminant_cct("D65") is None and D.illuminant_cct(-3) is None
    assert D.illuminant_cct(np.array([21], dtype=np.uint16)) == 6500.0


def test_illuminant_xy_of_cie_illuminants_and_planckian_codes():
    ccs = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
    for code, name in {17: "A", 18: "B", 19: "C", 20: "D55", 21: "D65", 22: "D75", 23: "D50", 3: "A"}.items():
        np.testing.assert_allclose(D.illuminant_xy(code), ccs[name], atol=5e-5)  # colour rounds to 4-5 digits
    for code in (2, 12, 13, 14, 15, 16, 24):  # fluorescent classes / studio tungsten: Planckian at the SDK CCT
        ref = colour.temperature.CCT_to_xy_Kang2002(D.illuminant_cct(code))
        np.testing.assert_allclose(D.illuminant_xy(code), ref, atol=1e-5)


@pytest.mark.parametrize("xy", [(0.3457, 0.3585), (0.4476, 0.4074), (0.3127, 0.329), (0.28, 0.29),
                                (0.52, 0.41), (0.40, 0.36), (0.33, 0.37)])
def test_robertson_cct_matches_colour(xy):
    from colour.models import UCS_to_uv, XYZ_to_UCS, xy_to_XYZ

    ref = colour.temperature.uv_to_CCT_Robertson1968(UCS_to_uv(XYZ_to_UCS(xy_to_XYZ(xy))))[0]
    assert D.xy_to_cct(xy) == pytest.approx(ref, rel=1e-9)


def test_mired_weight_closed_form_and_order():
    # 1/T interpolation: at T with 1/T = 0.5 (1/2850 + 1/6500) the weight is 0.5
    t = 1.0 / (0.5 * (1 / 2850 + 1 / 6500))
    assert D.mired_weight(t, 2850, 6500) == pytest.approx(0.5)
    assert D.mired_weight(t, 6500, 2850) == pytest.approx(0.5)
    assert D.mired_weight(2000, 2850, 6500) == 1.0 and D.mired_weight(9000, 2850, 6500) == 0.0
    assert D.mired_weight(2000, 6500, 2850) == 0.0 and D.mired_weight(9000, 6500, 2850) == 1.0
    m1, m2 = np.eye(3), 2 * np.eye(3)
    hd = H.matrix_interpolated(5000, 2850, 6500, m1, m2)
    g = D.mired_weight(5000, 2850, 6500)
    np.testing.assert_allclose(g * m1 + (1 - g) * m2, hd, atol=1e-12)


# -- real tag sets vs colour-hdri -------------------------------------------------------

@pytest.mark.parametrize("name", all_tag_sets())
def test_neutral_to_xy_fixed_point(name):
    t = load(name)
    prof = D.DngColorProfile.from_meta(meta_of(t))
    xy = D.camera_neutral_to_xy(prof, t["AsShotNeutral"])
    # colour-hdri maps the xy found back to the neutral (its own reverse direction)
    back = H.xy_to_camera_neutral(xy, *hdri_args(t)[:7])
    n = np.asarray(t["AsShotNeutral"]) / t["AsShotNeutral"][1]
    np.testing.assert_allclose(back, n, atol=1e-9)
    np.testing.assert_allclose(D.xy_to_camera_neutral(prof, xy), back, atol=1e-9)


@pytest.mark.parametrize("name, fm", [pytest.param(n, False, id=f"{n}-color_matrix") for n in DNGS + ["sidd"]]
                         + [pytest.param("sidd", True, id="sidd-forward_matrix")])
def test_camera_to_xyz_matches_colour_hdri(name, fm):
    t = load(name)
    if not fm:
        t = {k: v for k, v in t.items() if not k.startswith("ForwardMatrix")}
    prof = D.DngColorProfile.from_meta(meta_of(t))
    assert prof.has_forward_matrix == fm
    ours = D.camera_to_xyz_d50(prof, neutral=t["AsShotNeutral"])
    xy = D.camera_neutral_to_xy(prof, t["AsShotNeutral"])
    ref = H.matrix_camera_space_to_XYZ(xy, *hdri_args(t))
    np.testing.assert_allclose(ours, ref, atol=1e-6)
    if fm:  # the two paths really differ on this file (so the test tells them apart)
        other = D.camera_to_xyz_d50(prof, neutral=t["AsShotNeutral"], use_forward_matrix=False)
        assert np.abs(other - ours).max() > 1e-3


@pytest.mark.parametrize("name", ["gopro_hero7_iso252", "sidd"])
def test_as_shot_white_xy_path(name):
    t = load(name)
    prof = D.DngColorProfile.from_meta(meta_of(t))
    for xy in [(0.3457, 0.3585), (0.42, 0.40), (0.30, 0.315)]:
        ours = D.camera_to_xyz_d50(prof, xy=xy)
        ref = H.matrix_camera_space_to_XYZ(np.array(xy), *hdri_args(t))
        np.testing.assert_allclose(ours, ref, atol=1e-6)


@pytest.mark.parametrize("fm", [True, False], ids=["forward_matrix", "color_matrix"])
def test_camera_calibration_and_analog_balance(fm):
    """The real files carry identity CameraCalibration and unit AnalogBalance: exercise both."""
    t = dict(load("sidd"))
    t["CameraCalibration1"] = np.array([1.05, 0.01, 0.0, -0.02, 0.97, 0.01, 0.0, 0.03, 1.1])
    t["CameraCalibration2"] = np.array([0.95, 0.0, 0.02, 0.01, 1.02, 0.0, -0.01, 0.0, 0.9])
    t["AnalogBalance"] = np.array([1.2, 1.0, 0.85])
    if not fm:
        t = {k: v for k, v in t.items() if not k.startswith("ForwardMatrix")}
    prof = D.DngColorProfile.from_meta(meta_of(t))
    n = t["AsShotNeutral"]
    xy = D.camera_neutral_to_xy(prof, n)
    np.testing.assert_allclose(H.xy_to_camera_neutral(xy, *hdri_args(t)[:7]), n / n[1], atol=1e-9)
    ref = H.matrix_camera_space_to_XYZ(xy, *hdri_args(t))
    np.testing.assert_allclose(D.camera_to_xyz_d50(prof, neutral=n), ref, atol=1e-6)


def test_matrix_maps_neutral_to_d50_white():
    """Spec property: the camera neutral maps to the D50 white (any path), up to scale."""
    t = load("sidd")
    prof = D.DngColorProfile.from_meta(meta_of(t))
    n = t["AsShotNeutral"]
    for fm in (True, False):
        m = D.normalise_white_luminance(D.camera_to_xyz_d50(prof, neutral=n, use_forward_matrix=fm), n)
        xyz = m @ (n / n.max())
        assert xyz[1] == pytest.approx(1.0)
        np.testing.assert_allclose(D.xyz_to_xy(xyz), D.D50_XY, atol=2e-3 if fm else 1e-9)


def test_single_illuminant_when_code_unknown():
    t = load("gopro_hero7_iso252")
    meta = meta_of(t)
    meta.calibration_illuminant2 = 0  # unknown: CM2 must be ignored
    prof = D.DngColorProfile.from_meta(meta)
    assert not prof.dual
    ours = D.camera_to_xyz_d50(prof, neutral=t["AsShotNeutral"])
    xy = D.camera_neutral_to_xy(prof, t["AsShotNeutral"])
    eye = np.eye(3)
    ref = H.matrix_camera_space_to_XYZ(xy, 2850, 5000, meta.color_matrix1, eye, eye, eye, np.ones(3), eye, eye)
    np.testing.assert_allclose(ours, ref, atol=1e-6)


# -- bad input ------------------------------------------------------------------------------

def _one_line(exc):
    s = str(exc.value)
    assert "\n" not in s
    return s


def test_missing_color_matrix1():
    t = load("gopro_hero7_iso252")
    meta = meta_of(t)
    meta.color_matrix1 = None
    with pytest.raises(MetadataError) as exc:
        D.DngColorProfile.from_meta(meta)
    s = _one_line(exc)
    assert "ColorMatrix1" in s and t["source"] in s


def test_nan_in_matrix():
    meta = meta_of(load("gopro_hero7_iso252"))
    meta.color_matrix2 = meta.color_matrix2.copy()
    meta.color_matrix2[1, 1] = np.nan
    with pytest.raises(MetadataError) as exc:
        D.DngColorProfile.from_meta(meta)
    s = _one_line(exc)
    assert "ColorMatrix2" in s and "nan" in s and meta.source in s


def test_singular_matrix():
    meta = SimpleNamespace(color_matrix1=np.array([[1.0, 2, 3], [2, 4, 6], [0, 0, 1]]), source="x.dng")
    prof = D.DngColorProfile.from_meta(meta)
    with pytest.raises(MetadataError) as exc:
        D.camera_to_xyz_d50(prof, neutral=[0.5, 1.0, 0.6])
    s = _one_line(exc)
    assert "ColorMatrix1" in s and "singular" in s and "x.dng" in s


def test_bad_neutral_and_shape():
    prof = D.DngColorProfile.from_meta(SimpleNamespace(color_matrix1=np.eye(3), source="y.dng"))
    with pytest.raises(MetadataError, match="AsShotNeutral"):
        D.camera_to_xyz_d50(prof, neutral=[0.5, -1.0, 0.6])
    with pytest.raises(MetadataError, match="ColorMatrix1: expected a 3x3"):
        D.DngColorProfile.from_meta(SimpleNamespace(color_matrix1=np.ones(6), source="y.dng"))
