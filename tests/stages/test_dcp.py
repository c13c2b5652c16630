"""The ``dcp`` stage and its kernels: DNG camera profiles rendered as Adobe-style converters do.

Closed forms where they exist (ProPhoto matrix, HSV, table interpolation by CCT, hue wrap-around,
exposure ramp, natural spline, hue-preserving tone), identities (no-op tables leave the image
unchanged), consistency (embedded tags = the same tags in a .dcp) and, as an independent
reference, RawTherapee's own DCP implementation (``rawtherapee-cli``, slow and optional).
"""

from __future__ import annotations

import colorsys
import os
import shutil
import subprocess
import sys

import colour
import numpy as np
import pytest
from dcp_fixtures import FLOAT, LONG, SRATIONAL, TAG, add_ifd0_tags, identity_table, profile_tags, write_dcp
from shared_data import shared_path

from simcam.colour.dcp import (
    PROPHOTO_TO_XYZ_D50,
    XYZ_D50_TO_PROPHOTO,
    apply_hsv_table,
    exposure_ramp,
    exposure_tone,
    hsv_to_rgb,
    rgb_to_hsv,
    rgb_tone,
    spline_table,
)
from simcam.colour.dng import D50_XY, xy_to_xyz
from simcam.errors import DngError, PipelineError, StageError
from simcam.frame import RawFrame
from simcam.io.dng import read_dng
from simcam.io.sample_dng import make_test_dng, synthetic_meta
from simcam.pipeline import Pipeline, builtin_pipelines
from simcam.stages.dcp import Dcp

RNG = np.random.default_rng(7)


def _rgb(n=20000):
    rgb = RNG.uniform(0, 1, (n, 3)).astype(np.float32)
    rgb[:200] = rgb[:200, :1]  # greys
    rgb[200:206] = np.eye(3, dtype=np.float32).repeat(2, axis=0)  # primaries
    return rgb


def _hue_deg(rgb):
    h, s, v = rgb_to_hsv(*(np.ascontiguousarray(rgb[..., k], dtype=np.float32) for k in range(3)))
    return h * 60.0, s, v


# -- colour spaces and HSV -----------------------------------------------------------------------------

def test_prophoto_matrix_is_romm_rgb():
    # ROMM RGB -> XYZ (D50) as ISO 22028-2 tabulates it (and the DNG SDK's dng_space_ProPhoto)
    romm = np.array([[0.7977, 0.1352, 0.0313], [0.2880, 0.7119, 0.0001], [0.0, 0.0, 0.8249]])
    assert np.allclose(PROPHOTO_TO_XYZ_D50, romm, atol=2e-4)
    assert np.allclose(PROPHOTO_TO_XYZ_D50 @ np.ones(3), xy_to_xyz(D50_XY), atol=1e-12)
    assert np.allclose(XYZ_D50_TO_PROPHOTO @ PROPHOTO_TO_XYZ_D50, np.eye(3), atol=1e-12)


def test_hsv_matches_colorsys_and_round_trips():
    rgb = _rgb(5000)
    h, s, v = rgb_to_hsv(*(np.ascontiguousarray(rgb[:, k]) for k in range(3)))
    ref = np.array([colorsys.rgb_to_hsv(*map(float, c)) for c in rgb])
    hue_err = np.abs(((h / 6.0 - ref[:, 0]) + 0.5) % 1.0 - 0.5)
    assert np.all(hue_err[ref[:, 1] > 1e-3] < 1e-5)
    assert np.allclose(s, ref[:, 1], atol=1e-6) and np.allclose(v, ref[:, 2], atol=0)
    back = np.stack(hsv_to_rgb(h, s, v), axis=1)
    assert np.abs(back - rgb).max() < 1e-6


# -- hue/saturation/value tables ---------------------------------------------------------------------------

@pytest.mark.parametrize("dims,encoding", [((90, 30, 1), 0), ((6, 2, 1), 1), ((36, 8, 16), 0), ((12, 5, 7), 1), ((1, 2, 1), 0)])
def test_identity_table_leaves_colours_unchanged(dims, encoding):
    h, s, v = dims
    rgb = _rgb()
    channels = (np.ascontiguousarray(rgb[:, k]) for k in range(3))
    out = np.stack(apply_hsv_table(*channels, identity_table(h, s, v), encoding), axis=1)
    assert np.abs(out - rgb).max() < 1e-6


def _single_colour(hue_deg, sat=0.6, val=0.5):
    r, g, b = colorsys.hsv_to_rgb((hue_deg % 360) / 360.0, sat, val)
    return np.array([[r], [g], [b]], dtype=np.float32)


def test_hue_wraps_around_between_last_and_first_division():
    table = identity_table(6, 2, 1)  # divisions at 0, 60, ..., 300 degrees
    table[0, 5, :, 0] = 10.0  # shift at 300 degrees
    table[0, 0, :, 0] = 30.0  # shift at 0 degrees
    for hue, shift in [(330.0, 20.0), (355.0, 10.0 + 20.0 * 55.0 / 60.0), (0.0, 30.0), (300.0, 10.0),
                       (270.0, 5.0), (30.0, 15.0)]:
        r, g, b = _single_colour(hue)
        out = np.stack(apply_hsv_table(r, g, b, table), axis=1)
        got = _hue_deg(out)[0][0]
        expected = (hue + shift) % 360.0
        assert abs(((got - expected) + 180) % 360 - 180) < 2e-3, (hue, got, expected)
    # a negative shift across 0 degrees wraps to the top of the circle
    table = identity_table(6, 2, 1)
    table[..., 0] = -30.0
    out = np.stack(apply_hsv_table(*_single_colour(5.0), table), axis=1)
    assert abs(_hue_deg(out)[0][0] - 335.0) < 2e-3


def test_value_axis_with_srgb_encoding_interpolates_in_encoded_value():
    table = identity_table(1, 2, 3)  # value divisions at encoded 0, 0.5, 1
    table[1, ..., 2] = 0.5  # halve the value at encoded value 0.5
    v_lin = colour.cctf_decoding(0.25, function="sRGB")  # encoded 0.25: halfway between 0 and 0.5
    rgb = np.full((3, 1), v_lin, np.float32)
    out = np.stack(apply_hsv_table(*rgb, table, 1), axis=1)[0, 0]
    expected = colour.cctf_decoding(0.25 * 0.75, function="sRGB")  # encoded value scaled by 0.75, then decoded
    assert abs(out - expected) < 1e-6
    out_lin = np.stack(apply_hsv_table(*np.full((3, 1), 0.25, np.float32), table, 0), axis=1)[0, 0]
    assert abs(out_lin - 0.25 * 0.75) < 1e-6  # linear: index 0.25 * 2 = 0.5 -> scale 0.75


# -- the stage: helpers ---------------------------------------------------------------------------------------

def _camera_frame(rgb_prophoto, meta, stage):
    """A camera_rgb frame whose pixels the stage's matrix maps to the given linear ProPhoto values."""
    plan = stage.plan(meta)
    cam = np.linalg.solve(plan.matrix, np.asarray(rgb_prophoto, np.float64).reshape(-1, 3).T).T
    assert np.all(cam <= plan.clip + 1e-9), "test colour above the camera white"
    return RawFrame(cam.reshape(1, -1, 3).astype(np.float32), meta, kind="camera_rgb")


def _prophoto_out(frame):
    return (frame.data.reshape(-1, 3).astype(np.float64) @ XYZ_D50_TO_PROPHOTO.T)


def _meta(**kw):
    return synthetic_meta("RGGB", **kw)


# -- interpolation of the two maps by CCT (DNG 1.7.0.0 ch. 6), against a closed form ----------------------------

@pytest.mark.parametrize("cct_white", [2000.0, 2850.0, 3400.0, 4500.0, 5600.0, 6500.0, 9000.0])
def test_hue_sat_maps_interpolated_by_cct_closed_form(tmp_path, cct_white):
    t1, t2 = identity_table(12, 4, 1), identity_table(12, 4, 1)
    t1[..., 0], t1[..., 1] = 12.0, 1.2  # illuminant A (2850 K in the DNG SDK's table)
    t2[..., 0], t2[..., 1] = -6.0, 0.9  # D65 (6500 K)
    path = write_dcp(tmp_path / "two.dcp", profile_tags(hsm1=t1, hsm2=t2))
    stage = Dcp(path=str(path), shadows=0.0)
    xy = colour.temperature.CCT_to_xy_Kang2002(cct_white)
    meta = _meta(as_shot_neutral=None, as_shot_white_xy=np.asarray(xy))
    # closed form: weight of map 1 linear in 1/T between the calibration CCTs, clamped; T by Robertson (colour-science)
    T = float(colour.temperature.uv_to_CCT_Robertson1968(colour.xy_to_UCS_uv(xy))[0])
    g = float(np.clip((1 / T - 1 / 6500.0) / (1 / 2850.0 - 1 / 6500.0), 0.0, 1.0))
    plan = stage.plan(meta)
    assert np.allclose(plan.hue_sat_map[..., 0], g * 12.0 + (1 - g) * -6.0, atol=1e-5)
    assert np.allclose(plan.hue_sat_map[..., 1], g * 1.2 + (1 - g) * 0.9, atol=1e-6)
    # and on pixels: hue + shift, saturation x scale (a colour well inside the cube)
    hue, sat, val = 100.0, 0.4, 0.3
    frame = _camera_frame(_single_colour(hue, sat, val).T, meta, stage)
    h_out, s_out, v_out = _hue_deg(_prophoto_out(stage(frame)))
    assert abs(h_out[0] - (hue + g * 12.0 + (1 - g) * -6.0)) < 1e-2
    assert abs(s_out[0] - sat * (g * 1.2 + (1 - g) * 0.9)) < 1e-4 and abs(v_out[0] - val) < 1e-4


def test_identity_tables_leave_the_render_unchanged(tmp_path):
    plain = write_dcp(tmp_path / "plain.dcp", profile_tags())
    ident = write_dcp(tmp_path / "ident.dcp", profile_tags(hsm1=identity_table(90, 30, 1), hsm2=identity_table(90, 30, 1),
                                                           look=identity_table(36, 8, 16), look_encoding=1))
    meta = _meta()
    data = RNG.uniform(0, 0.45, (24, 32, 3)).astype(np.float32)
    frame = RawFrame(data, meta, kind="camera_rgb")
    a = Dcp(path=str(plain), shadows=0.0)(frame).data
    b = Dcp(path=str(ident), shadows=0.0)(frame).data
    assert np.abs(a - b).max() < 1e-6
    # and without any profile tables the stage is camera_to_xyz clipped to [0, 1] in ProPhoto
    from simcam.stages.camera_to_xyz import CameraToXYZ

    meta_fm = _meta(color_matrix1=np.array(profile_tags()[0][2]), color_matrix2=np.array(profile_tags()[1][2]),
                    calibration_illuminant1=17, calibration_illuminant2=21)
    frame2 = RawFrame(data, meta_fm, kind="camera_rgb")
    ref = CameraToXYZ(use_forward_matrix=False)(frame2).data.reshape(-1, 3) @ XYZ_D50_TO_PROPHOTO.T
    ref = np.clip(ref, 0, 1) @ PROPHOTO_TO_XYZ_D50.T
    got = Dcp(path=str(write_dcp(tmp_path / "cm.dcp", profile_tags(forward=False))), shadows=0.0)(frame2).data
    assert np.abs(got.reshape(-1, 3) - ref).max() < 2e-6


# -- exposure, black, tone ------------------------------------------------------------------------------------------

def test_exposure_ramp_closed_form():
    x = np.linspace(0, 1, 100001, dtype=np.float32)
    y = exposure_ramp(x, 1.0, 0.0)  # +1 EV: x * 2, clipped at 1
    assert np.allclose(y, np.minimum(2 * x, 1), atol=1e-6)
    black = 0.005
    y = exposure_ramp(x, 0.0, black)
    r = min(black / 2, (1 - black) / 16)
    slope = 1 / (1 - black)
    above = x >= black + r
    assert np.allclose(y[above], np.minimum((x[above] - black) * slope, 1), atol=1e-6)
    assert np.all(y[x <= black - r] == 0)
    mid = (x > black - r) & (x < black + r)
    assert np.allclose(y[mid], slope / (4 * r) * (x[mid] - black + r) ** 2, atol=1e-7)
    # the toe meets the line with the same value and slope at black + r
    assert abs(slope / (4 * r) * (2 * r) ** 2 - r * slope) < 1e-12 and abs(slope / (4 * r) * 2 * (2 * r) - slope) < 1e-12
    assert np.all(np.diff(y) >= 0)


def test_exposure_tone_darkens_and_keeps_white():
    k = 2.0 ** -1.0
    x = np.linspace(0, 1, 1001)
    y = exposure_tone(x, -1.0)
    assert np.allclose(y[x <= 0.25], x[x <= 0.25] * k) and abs(y[-1] - 1) < 1e-12
    assert np.all(np.diff(y) > 0)
    eps = 1e-7
    left = (exposure_tone(0.25, -1.0) - exposure_tone(0.25 - eps, -1.0)) / eps
    right = (exposure_tone(0.25 + eps, -1.0) - exposure_tone(0.25, -1.0)) / eps
    assert abs(left - right) < 1e-5
    assert np.array_equal(exposure_tone(x, 0.5), x)


def test_tone_curve_is_the_natural_cubic_spline():
    table = spline_table(np.array([[0, 0], [0.5, 0.7], [1, 1]]))
    x = np.linspace(0, 1, table.size)
    # closed form of the natural spline through (0, 0), (0.5, 0.7), (1, 1): M1 = -2.4, M0 = M2 = 0
    expected = np.where(x <= 0.5, -0.8 * x ** 3 + 1.6 * x, -0.8 * (1 - x) ** 3 + 1.6 * (1 - x) + 2 * (x - 0.5))
    assert np.abs(table - expected).max() < 1e-6
    assert spline_table(np.array([[0, 0], [1, 1]])) is not None
    assert np.allclose(spline_table(np.array([[0, 0], [1, 1]])), x, atol=1e-7)
    assert spline_table(None) is None and spline_table(None, 0.5) is None


def test_rgb_tone_preserves_hue_and_maps_greys_by_the_curve():
    table = spline_table(np.array([[0, 0], [0.25, 0.4], [0.6, 0.8], [1, 1]]))
    rgb = _rgb()
    out = np.stack(rgb_tone(*(np.ascontiguousarray(rgb[:, k]) for k in range(3)), table), axis=1)
    h0, s0, _ = _hue_deg(rgb)
    h1, s1, _ = _hue_deg(out)
    coloured = s0 > 0.05
    assert np.abs(((h1 - h0) + 180) % 360 - 180)[coloured].max() < 0.05
    lut = lambda v: np.interp(v, np.linspace(0, 1, table.size), table)  # noqa: E731
    assert np.allclose(out.max(axis=1), lut(rgb.max(axis=1)), atol=1e-6)
    assert np.allclose(out.min(axis=1), lut(rgb.min(axis=1)), atol=1e-6)
    assert np.allclose(out[:200], lut(rgb[:200]), atol=1e-6)  # greys


def test_plan_exposure_black_and_tone_from_the_profile(tmp_path):
    path = write_dcp(tmp_path / "e.dcp", profile_tags(baseline_offset=1.0, black_render=1, tone=[[0, 0], [0.5, 0.6], [1, 1]]))
    meta = _meta(baseline_exposure=0.5)
    plan = Dcp(path=str(path)).plan(meta)
    assert plan.exposure == 1.5 and plan.black == 0.0 and plan.tone_table is not None
    plan = Dcp(path=str(path), baseline_exposure=False, exposure=-0.5, shadows=10.0, apply_tone_curve=False).plan(meta)
    assert plan.exposure == -0.5 and plan.black == 0.01
    assert np.allclose(plan.tone_table, exposure_tone(np.linspace(0, 1, plan.tone_table.size), -0.5), atol=1e-6)
    auto = write_dcp(tmp_path / "auto.dcp", profile_tags())
    assert Dcp(path=str(auto)).plan(meta).black == 0.005  # DefaultBlackRender Auto: Camera Raw's Shadows 5
    # +1.5 EV on a grey below white/2^1.5: the linear value is multiplied by 2^1.5
    stage = Dcp(path=str(path), apply_tone_curve=False)
    frame = _camera_frame([[0.1, 0.1, 0.1]], meta, stage)
    assert np.allclose(_prophoto_out(stage(frame)), 0.1 * 2 ** 1.5, atol=1e-5)


# -- sources, parameters, errors -------------------------------------------------------------------------------------

def test_stage_parameter_errors(tmp_path):
    with pytest.raises(StageError, match="dcp: path: expected"):
        Dcp(source="file")
    with pytest.raises(StageError, match="given with source 'embedded'"):
        Dcp(source="embedded", path="x.dcp")
    with pytest.raises(StageError, match="dcp: shadows"):
        Dcp(shadows=500.0)
    with pytest.raises(StageError, match="dcp: exposure"):
        Dcp(exposure=float("nan"))
    with pytest.raises(DngError, match="no such file"):
        Dcp(path=str(tmp_path / "missing.dcp"))
    bad = tmp_path / "bad.dcp"
    bad.write_bytes(b"II*\0" + bytes(20))
    with pytest.raises(PipelineError, match=r"stages\[10\] \(dcp\): .*bad.dcp: header: .*not a camera profile"):
        Pipeline.from_yaml("srgb-dcp").with_overrides({"dcp.path": str(bad)})
    with pytest.raises(PipelineError):
        Pipeline.from_dict({"version": 1, "stages": [{"type": "dcp", "bogus": 1}]})


def test_embedded_tags_render_like_the_same_tags_in_a_dcp(tmp_path):
    hsm1, hsm2 = identity_table(18, 6, 1), identity_table(18, 6, 1)
    hsm1[..., 0] = np.linspace(-15, 15, 18)[None, :, None]
    hsm2[..., 1] = 1.15
    look = identity_table(12, 5, 4)
    look[..., 2] = np.linspace(0.9, 1.1, 4)[:, None, None]
    tone = [[0, 0], [0.3, 0.42], [0.7, 0.85], [1, 1]]
    dng = make_test_dng(tmp_path / "e.dng", 48, 64, "RGGB", seed=3)
    meta = read_dng(dng).meta
    tables = [(TAG["ProfileHueSatMapDims"], LONG, [18, 6, 1]), (TAG["ProfileHueSatMapData1"], FLOAT, hsm1.ravel()),
              (TAG["ProfileHueSatMapData2"], FLOAT, hsm2.ravel()), (TAG["ProfileLookTableDims"], LONG, [12, 5, 4]),
              (TAG["ProfileLookTableData"], FLOAT, look.ravel()), (TAG["ProfileLookTableEncoding"], LONG, 1),
              (TAG["ProfileToneCurve"], FLOAT, np.ravel(tone)), (TAG["BaselineExposureOffset"], SRATIONAL, 0.3)]
    add_ifd0_tags(dng, tables)
    dcp = write_dcp(tmp_path / "same.dcp", [(TAG["ColorMatrix1"], SRATIONAL, meta.color_matrix1),
                                            (TAG["ColorMatrix2"], SRATIONAL, meta.color_matrix2),
                                            (TAG["CalibrationIlluminant1"], LONG, meta.calibration_illuminant1),
                                            (TAG["CalibrationIlluminant2"], LONG, meta.calibration_illuminant2)] + tables)
    frame = read_dng(dng)
    embedded = Pipeline.from_yaml("srgb-dcp")(frame).data
    from_file = Pipeline.from_yaml("srgb-dcp").with_overrides({"dcp.path": str(dcp)})(frame).data
    plain = Pipeline.from_yaml("srgb-dcp").with_overrides({"dcp.apply_hue_sat_map": False})(frame).data
    # the DCP's matrices are the DNG's rounded to 1/10000 (SRATIONAL): equal to that precision
    assert np.abs(embedded - from_file).max() < 2e-3
    assert np.abs(embedded - plain).max() > 1e-2  # the embedded tables did act


def test_builtin_pipeline_and_stage_node():
    assert "srgb-dcp" in builtin_pipelines()
    pipe = Pipeline.from_yaml("srgb-dcp")
    types = [s.type for s in pipe.stages]
    assert types[types.index("dcp") + 1:] == ["xyz_to_srgb", "clip", "gamma", "orientation"]
    assert Dcp(exposure=0.5).to_node() == {"type": "dcp", "exposure": 0.5}


# -- real files ----------------------------------------------------------------------------------------------------------

@pytest.mark.shared_data
def test_cli_renders_a_shared_dng_with_a_shared_dcp(tmp_path):
    dng, dcp = shared_path("dng/canon_550d_colorchecker.dng"), shared_path("dcp/Canon_EOS_550D.dcp")
    out = tmp_path / "x.png"
    r = subprocess.run([sys.executable, "-m", "simcam", "render", str(dng), "-p", "srgb-dcp", "--set", f"dcp.path={dcp}",
                        "-o", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    from simcam.io.images import read_image

    img = np.asarray(read_image(out))
    assert img.shape[:2] == (1156, 1734)
    r = subprocess.run([sys.executable, "-m", "simcam", "render", str(dng), "-p", "srgb-dcp", "--set",
                        f"dcp.path={tmp_path / 'nope.dcp'}", "-o", str(tmp_path / "y.png")], capture_output=True, text=True)
    assert r.returncode == 2 and "nope.dcp: no such file" in r.stderr and len(r.stderr.strip().splitlines()) == 1


# -- an independent reference: RawTherapee's DCP implementation ------------------------------------------------------------

_PP3 = """[Version]
AppVersion=5.9
Version=346

[Color Management]
InputProfile=file:{dcp}
ToneCurve=true
ApplyLookTable=true
ApplyBaselineExposureOffset=true
ApplyHueSatMap=true
DCPIlluminant=0
WorkingProfile=ProPhoto
WorkingTRC=none
OutputProfile=RTv4_sRGB
OutputProfileIntent=Relative
OutputBPC=true
"""


def _lab(img16):
    xyz = colour.sRGB_to_XYZ(img16.astype(np.float64) / 65535.0)
    return colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])


def _block(x, k):
    h, w = (x.shape[0] // k) * k, (x.shape[1] // k) * k
    return x[:h, :w].reshape(h // k, k, w // k, k, -1).mean(axis=(1, 3))


def delta_e_vs_rawtherapee(dng, dcp, tmp_path, overrides=None, block=8):
    """(full-resolution, block-averaged) mean CIEDE2000 of simcam's srgb-dcp render vs rawtherapee-cli's.

    RawTherapee (5.9): neutral processing profile, camera white balance, the DCP as input profile with
    HueSatMap, LookTable, tone curve and BaselineExposureOffset, ProPhoto working space, sRGB output,
    AMaZE demosaic; it applies no DefaultBlackRender black point (simcam: ``shadows 0``) and no DNG
    GainMaps (simcam: ``lens_shading.strength 0``), ignores the EXIF orientation of these files
    (simcam: ``orientation.value 1``) and crops 4 pixels per side (aligned by search).
    """
    import tifffile

    pp3 = tmp_path / "dcp.pp3"
    pp3.write_text(_PP3.format(dcp=dcp))
    rt_out = tmp_path / "rt.tif"
    env = dict(os.environ, HOME=str(tmp_path))  # RawTherapee writes its settings under $HOME
    r = subprocess.run(["rawtherapee-cli", "-q", "-o", str(rt_out), "-p", str(pp3), "-t", "-b16", "-Y", "-c", str(dng)],
                       capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0 and rt_out.exists(), r.stdout + r.stderr
    rt = tifffile.imread(rt_out)
    ov = {"dcp.path": str(dcp), "dcp.shadows": 0.0, "lens_shading.strength": 0.0, "orientation.value": 1, **(overrides or {})}
    sim = Pipeline.from_yaml("srgb-dcp").with_overrides(ov)(read_dng(dng)).data
    sim = np.round(np.clip(sim, 0, 1) * 65535).astype(np.uint16)
    H, W = rt.shape[:2]
    best = min(((np.mean((sim[dy:dy + H:4, dx:dx + W:4, 1].astype(float) - rt[::4, ::4, 1]) ** 2), dy, dx)
                for dy in range(sim.shape[0] - H + 1) for dx in range(sim.shape[1] - W + 1)))
    sim = sim[best[1]:best[1] + H, best[2]:best[2] + W]
    rt, sim = rt[8:-8, 8:-8], sim[8:-8, 8:-8]  # demosaic borders
    full = colour.delta_E(_lab(rt), _lab(sim), method="CIE 2000")
    blk = colour.delta_E(_lab(_block(rt.astype(float), block)), _lab(_block(sim.astype(float), block)), method="CIE 2000")
    return float(full.mean()), float(blk.mean())


#: (DNG, DCP, limit on the full-resolution mean dE00, limit on the 8x8-block mean dE00); measured
#: (RawTherapee 5.9, Debian 12): Canon 1.64 / 0.38, HERO7 + LG 2.65 / 0.81, HERO7 + Galaxy S7 1.86 / 0.54.
RT_CASES = [("canon_550d_colorchecker", "Canon_EOS_550D", 2.5, 0.8),
            ("gopro_hero7_iso252", "LG_Mobile_LG-H815", 3.5, 1.3),
            ("gopro_hero7_iso252", "samsung_SM-G930V", 3.0, 1.1)]


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("dng,dcp,full_max,block_max", RT_CASES)
def test_render_matches_rawtherapee(tmp_path, dng, dcp, full_max, block_max):
    if shutil.which("rawtherapee-cli") is None:
        pytest.skip("rawtherapee-cli not installed (Debian: apt-get install rawtherapee)")
    full, blk = delta_e_vs_rawtherapee(shared_path(f"dng/{dng}.dng"), shared_path(f"dcp/{dcp}.dcp"), tmp_path)
    print(f"{dng} + {dcp}: mean dE00 {full:.3f} (full resolution), {blk:.3f} (8x8 blocks)")
    assert full < full_max and blk < block_max
