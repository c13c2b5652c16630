"""The colour / display stages: white_balance, camera_to_xyz, orientation, clip, quantize, pipelines."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.colour import dng as D
from simcam.errors import MetadataError, PipelineError, StageError
from simcam.frame import CameraMeta, RawFrame
from simcam.stages.camera_to_xyz import CameraToXYZ
from simcam.stages.clip import Clip, Quantize
from simcam.stages.orientation import Orientation
from simcam.stages.white_balance import WhiteBalance

# SIDD 0001 (Galaxy S6 edge) colour tags, as floats (ColorMatrix/ForwardMatrix in row order).
CM1 = np.array([0.6640625, -0.04589844, -0.12011719, -0.54296875, 1.43847656, 0.07128906,
                -0.17675781, 0.40527344, 0.47558594]).reshape(3, 3)
CM2 = np.array([1.23828125, -0.44433594, -0.27832031, -0.45019531, 1.46972656, 0.06933594,
                -0.08984375, 0.29199219, 0.61328125]).reshape(3, 3)
FM1 = np.array([0.74609375, -0.01953125, 0.23730469, 0.28320312, 0.703125, 0.01269531,
                0.02539062, -0.45605469, 1.25585938]).reshape(3, 3)
FM2 = np.array([0.62988281, 0.01855469, 0.31542969, 0.16503906, 0.77636719, 0.05859375,
                0.01855469, -0.84960938, 1.65625]).reshape(3, 3)
NEUTRAL = np.array([0.55273438, 1.0, 0.484375])


def meta(**kw):
    base = dict(cfa="GRBG", color_matrix1=CM1, color_matrix2=CM2, forward_matrix1=FM1, forward_matrix2=FM2,
                calibration_illuminant1=21, calibration_illuminant2=17, as_shot_neutral=NEUTRAL, source="s6.dng")
    base.update(kw)
    return CameraMeta(**base)


def rgb_frame(m=None, seed=0, shape=(4, 6)):
    data = np.random.default_rng(seed).uniform(0.05, 0.9, size=shape + (3,))
    return RawFrame(data, m or meta(), "camera_rgb")


# -- white balance ------------------------------------------------------------------------

@pytest.mark.parametrize("cfa", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_white_balance_mosaic_per_site(cfa):
    m = meta(cfa=cfa)
    mosaic = np.random.default_rng(1).uniform(0, 1, size=(6, 8)).astype(np.float32)
    out = WhiteBalance(source="as_shot")(RawFrame(mosaic, m, "raw"))
    gains = {"R": 1 / NEUTRAL[0], "G": 1.0, "B": 1 / NEUTRAL[2]}
    for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        np.testing.assert_allclose(out.data[dy::2, dx::2], mosaic[dy::2, dx::2] * gains[cfa[k]], rtol=1e-6)
    np.testing.assert_allclose(out.meta.white_balance_gains, [gains["R"], 1.0, gains["B"]])
    assert m.white_balance_gains is None  # the input metadata is untouched


def test_white_balance_explicit_gains_neutral_and_none():
    f = rgb_frame()
    out = WhiteBalance(source="gains", gains=[4.0, 2.0, 3.0])(f)
    np.testing.assert_allclose(out.meta.white_balance_gains, [2.0, 1.0, 1.5])
    np.testing.assert_allclose(out.data, f.data * np.float32([2.0, 1.0, 1.5]), rtol=1e-6)
    out = WhiteBalance(source="neutral", neutral=[0.5, 2.0, 1.0])(f)
    np.testing.assert_allclose(out.meta.white_balance_gains, [4.0, 1.0, 2.0])
    twice = WhiteBalance(source="gains", gains=[2.0, 1.0, 1.0])(out)
    np.testing.assert_allclose(twice.meta.white_balance_gains, [8.0, 1.0, 2.0])  # composed
    same = WhiteBalance(source="none")(f)
    assert same.data is f.data and same.meta.white_balance_gains is None


def test_white_balance_as_shot_white_xy():
    m = meta(as_shot_neutral=None, as_shot_white_xy=np.array([0.40, 0.39]))
    out = WhiteBalance()(rgb_frame(m))
    n = D.xy_to_camera_neutral(D.DngColorProfile.from_meta(m), [0.40, 0.39])
    np.testing.assert_allclose(out.meta.white_balance_gains, 1 / n, rtol=1e-9)


def test_white_balance_errors():
    with pytest.raises(MetadataError, match="s6.dng: AsShotNeutral: missing"):
        WhiteBalance()(rgb_frame(meta(as_shot_neutral=None)))
    with pytest.raises(StageError, match="neutral"):
        WhiteBalance(source="neutral")
    with pytest.raises(StageError, match="gains"):
        WhiteBalance(source="gains", gains=[1.0, 0.0, 1.0])


# -- camera_to_xyz ---------------------------------------------------------------------------

@pytest.mark.parametrize("fm", [True, False])
def test_camera_to_xyz_is_the_dng_matrix_normalised(fm):
    f = rgb_frame()
    out = CameraToXYZ(use_forward_matrix=fm)(f)
    prof = D.DngColorProfile.from_meta(f.meta)
    m = D.normalise_white_luminance(D.camera_to_xyz_d50(prof, neutral=NEUTRAL, use_forward_matrix=fm), NEUTRAL)
    assert out.kind == "xyz" and out.data.dtype == np.float32
    np.testing.assert_allclose(out.data, f.data @ m.T, atol=1e-5)
    # the white at clipping -> Y = 1, chromaticity D50
    w = CameraToXYZ(use_forward_matrix=fm)(RawFrame(np.broadcast_to(NEUTRAL, (1, 1, 3)), f.meta, "camera_rgb"))
    assert w.data[0, 0, 1] == pytest.approx(1.0, abs=1e-5)
    np.testing.assert_allclose(D.xyz_to_xy(w.data[0, 0].astype(np.float64)), D.D50_XY, atol=2e-3)


@pytest.mark.parametrize("fm", [True, False])
def test_camera_to_xyz_undoes_white_balance(fm):
    f = rgb_frame()
    plain = CameraToXYZ(use_forward_matrix=fm)(f)
    balanced = WhiteBalance()(f)
    after = CameraToXYZ(use_forward_matrix=fm)(balanced)
    np.testing.assert_allclose(after.data, plain.data, atol=2e-5)
    # an explicit neutral: balanced with it, converted with the white it implies (auto)
    n = [0.6, 1.0, 0.45]
    a = CameraToXYZ(white="neutral", neutral=n, use_forward_matrix=fm)(f)
    b = CameraToXYZ(use_forward_matrix=fm)(WhiteBalance(source="neutral", neutral=n)(f))
    np.testing.assert_allclose(a.data, b.data, atol=2e-5)


def test_camera_to_xyz_xy_white_and_sidd_mode():
    f = rgb_frame()
    out = CameraToXYZ(white="xy", xy=[0.3457, 0.3585])(f)
    prof = D.DngColorProfile.from_meta(f.meta)
    n = D.xy_to_camera_neutral(prof, D.D50_XY)
    m = D.normalise_white_luminance(D.camera_to_xyz_d50(prof, xy=D.D50_XY), n)
    np.testing.assert_allclose(out.data, f.data @ m.T, atol=1e-5)
    sidd = CameraToXYZ(mode="sidd")(WhiteBalance()(f))
    rownorm = CM1 / CM1.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(sidd.data, WhiteBalance()(f).data @ np.linalg.inv(rownorm).T, atol=1e-5)


def test_camera_to_xyz_errors():
    with pytest.raises(MetadataError, match="s6.dng: ColorMatrix1: missing"):
        CameraToXYZ()(rgb_frame(meta(color_matrix1=None)))
    bad = CM2.copy()
    bad[0, 0] = np.nan
    with pytest.raises(MetadataError, match="ColorMatrix2: expected finite"):
        CameraToXYZ()(rgb_frame(meta(color_matrix2=bad)))
    with pytest.raises(MetadataError, match="singular"):
        CameraToXYZ(use_forward_matrix=False)(rgb_frame(meta(color_matrix1=np.ones((3, 3)), color_matrix2=None)))
    with pytest.raises(StageError):
        CameraToXYZ(white="neutral")


# -- orientation -------------------------------------------------------------------------------

@pytest.mark.parametrize("value", range(1, 9))
def test_orientation_matches_pil_exif_transpose(value):
    from PIL import Image, ImageOps

    rng = np.random.default_rng(value)
    img = rng.integers(0, 256, size=(3, 5, 3), dtype=np.uint8)
    pil = Image.fromarray(img)
    exif = pil.getexif()
    exif[0x0112] = value
    pil.info["exif"] = exif.tobytes()
    ref = np.asarray(ImageOps.exif_transpose(pil))
    out = Orientation()(RawFrame(img.astype(np.float32), meta(orientation=value), "linear_srgb"))
    np.testing.assert_array_equal(out.data, ref.astype(np.float32))
    assert out.meta.orientation == 1
    explicit = Orientation(value=value)(RawFrame(img.astype(np.float32), meta(orientation=1), "display"))
    np.testing.assert_array_equal(explicit.data, ref.astype(np.float32))


def test_orientation_sidd_convention_and_errors():
    img = np.arange(2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    f2 = Orientation(convention="sidd")(RawFrame(img, meta(orientation=2), "linear_srgb"))
    np.testing.assert_array_equal(f2.data, img[::-1])  # cv2.flip(img, 0): upside down
    f5 = Orientation(convention="sidd")(RawFrame(img, meta(orientation=5), "linear_srgb"))
    np.testing.assert_array_equal(f5.data, np.rot90(img[::-1], 1))  # flip(0) then 90 deg CCW
    f7 = Orientation(convention="sidd")(RawFrame(img, meta(orientation=7), "linear_srgb"))
    np.testing.assert_array_equal(f7.data, np.rot90(img[::-1], -1))  # flip(0) then 90 deg CW
    with pytest.raises(StageError):
        Orientation(value=9)
    with pytest.raises(MetadataError, match="Orientation"):
        Orientation()(RawFrame(img, meta(orientation=0), "linear_srgb"))


# -- clip / quantize -----------------------------------------------------------------------------

def test_clip():
    x = np.linspace(-1, 2, 4 * 6 * 3).reshape(4, 6, 3)
    f = RawFrame(x, meta(), "linear_srgb")
    np.testing.assert_array_equal(Clip()(f).data, np.clip(x, 0, 1).astype(np.float32))
    np.testing.assert_array_equal(Clip(low=None, high=1.5)(f).data, np.minimum(x, 1.5).astype(np.float32))
    np.testing.assert_array_equal(Clip(low=-0.5, high=None)(f).data, np.maximum(x, -0.5).astype(np.float32))
    mosaic = RawFrame(x[..., 0], meta(), "raw")
    assert Clip()(mosaic).data.max() == 1.0
    with pytest.raises(StageError):
        Clip(low=1.0, high=0.0)
    with pytest.raises(StageError):
        Clip()(RawFrame(x[..., 0], meta(), "raw_dn"))


@pytest.mark.parametrize("bits", [1, 2, 8, 12, 16])
def test_quantize(bits):
    x = np.random.default_rng(bits).uniform(-0.1, 1.1, size=(5, 7, 3))
    out = Quantize(bits=bits)(RawFrame(x, meta(), "display"))
    n = 2 ** bits - 1
    assert out.data.dtype == np.float32
    levels = out.data.astype(np.float64) * n
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-3 * max(1, n / 4096))
    assert np.abs(out.data - np.clip(x, 0, 1)).max() <= 0.5 / n + 1e-6
    assert np.unique(Quantize(bits=1)(RawFrame(x, meta(), "display")).data).tolist() == [0.0, 1.0]
    with pytest.raises(StageError):
        Quantize(bits=17)


# -- pipelines -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["srgb", "linear-srgb", "sidd-srgb"])
def test_builtin_pipelines_validate(name):
    from simcam.pipeline import Pipeline
    from simcam.stages import stage_types

    missing = {"demosaic", "lens_shading"} - set(stage_types())
    if missing:
        pytest.skip(f"stage types {sorted(missing)} not in this tree yet")
    p = Pipeline.from_yaml(name)
    assert p.output_kind == {"srgb": "display", "linear-srgb": "linear_srgb", "sidd-srgb": "display"}[name]
    assert Pipeline.from_yaml(p.to_yaml()).to_dict() == p.to_dict()


def test_bad_param_in_yaml():
    from simcam.pipeline import Pipeline

    with pytest.raises(PipelineError, match=r"stages\[0\].*curve"):
        Pipeline.from_yaml("version: 1\ninput: linear_srgb\nstages:\n  - type: gamma\n    curve: rec709\n")


def test_sidd_chain_reproduces_simple_camera_pipeline_after_demosaic():
    """camera RGB -> display through the sidd-srgb stages vs simple-camera-pipeline's formulas
    (python/pipeline_utils.py: apply_color_space_transform, transform_xyz_to_srgb, fix_orientation
    for orientation 3, apply_gamma, and its simple tone curve), written out here in numpy."""
    from simcam.pipeline import Pipeline

    rng = np.random.default_rng(5)
    wb = rng.uniform(0.0, 1.0, size=(6, 9, 3))  # white-balanced, clipped camera RGB
    # their formulas
    xyz2cam = CM1 / np.sum(CM1, axis=1, keepdims=True)
    xyz = np.clip(np.einsum("ij,hwj->hwi", np.linalg.inv(xyz2cam), wb), 0.0, 1.0)
    xyz2srgb = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                         [0.0556434, -0.2040259, 1.0572252]])
    xyz2srgb = xyz2srgb / np.sum(xyz2srgb, axis=-1, keepdims=True)
    srgb = np.clip(np.einsum("ij,hwj->hwi", xyz2srgb, xyz), 0.0, 1.0)
    srgb = srgb[::-1, ::-1]  # orientation 3: rotate 180
    g = srgb ** (1.0 / 2.2)
    ref = 3 * g ** 2 - 2 * g ** 3
    yaml = """
version: 1
input: camera_rgb
stages:
  - {type: camera_to_xyz, mode: sidd}
  - {type: clip, low: 0.0, high: 1.0}
  - {type: xyz_to_srgb, mode: sidd}
  - {type: clip, low: 0.0, high: 1.0}
  - {type: orientation, convention: sidd}
  - {type: gamma, curve: power, exponent: 0.45454545454545453}
  - {type: tone, curve: sidd}
"""
    m = meta(orientation=3, white_balance_gains=1.0 / NEUTRAL)
    out = Pipeline.from_yaml(yaml)(RawFrame(wb, m, "camera_rgb"))
    assert out.kind == "display"
    np.testing.assert_allclose(out.data, ref, atol=2e-5)
