"""Display transforms against colour-science and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.colour import display as disp
from simcam.frame import CameraMeta, RawFrame
from simcam.stages.gamma import Gamma
from simcam.stages.tone import Tone
from simcam.stages.xyz_to_srgb import XYZToSRGB

colour = pytest.importorskip("colour")

D50 = np.array([0.3457, 0.3585])


def _frame(data, kind):
    return RawFrame(np.asarray(data, dtype=np.float32), CameraMeta(), kind)


def test_xyz_d50_to_linear_srgb_matches_colour():
    rng = np.random.default_rng(0)
    xyz = rng.uniform(0.0, 1.0, size=(4, 5, 3))
    ref = colour.XYZ_to_RGB(xyz, "sRGB", illuminant=D50, chromatic_adaptation_transform="Bradford",
                            apply_cctf_encoding=False)
    m = disp.xyz_d50_to_linear_srgb_matrix()
    np.testing.assert_allclose(xyz @ m.T, ref, atol=1e-6)  # float64 matrix
    out = XYZToSRGB()(_frame(xyz, "xyz"))
    assert out.kind == "linear_srgb" and out.data.dtype == np.float32
    np.testing.assert_allclose(out.data, ref, atol=1e-6)  # float32 kernel, |values| < 2.5


def test_d50_white_maps_to_srgb_white():
    white = np.array([0.3457 / 0.3585, 1.0, (1 - 0.3457 - 0.3585) / 0.3585])
    np.testing.assert_allclose(disp.xyz_d50_to_linear_srgb_matrix() @ white, 1.0, atol=2e-4)  # 4-digit IEC matrix


def test_sidd_xyz_to_srgb_rows_sum_to_one():
    m = disp.sidd_xyz_to_srgb_matrix()
    np.testing.assert_allclose(m.sum(axis=1), 1.0, atol=1e-12)
    out = XYZToSRGB(mode="sidd")(_frame(np.ones((1, 1, 3)), "xyz"))
    np.testing.assert_allclose(out.data, 1.0, atol=1e-6)


def test_srgb_oetf_matches_colour():
    x = np.concatenate([np.linspace(0, 0.01, 101), np.linspace(0.01, 1, 1001), [0.0031308, 1.2, -0.01]])
    ref = colour.cctf_encoding(x, function="sRGB")
    np.testing.assert_allclose(disp.srgb_oetf(x), ref, atol=1e-6)
    out = Gamma(curve="srgb")(_frame(np.tile(x[:1100, None], (1, 3)).reshape(1100, 1, 3), "linear_srgb"))
    assert out.kind == "display"
    np.testing.assert_allclose(out.data[:, 0, 0], ref[:1100], atol=1e-6)


def test_power_gamma():
    x = np.linspace(0, 1, 64).reshape(8, 8, 1).repeat(3, axis=2)
    out = Gamma(curve="power")(_frame(x, "linear_srgb"))
    np.testing.assert_allclose(out.data, x ** (1 / 2.2), atol=1e-6)
    out = Gamma(curve="power", exponent=0.5)(_frame(-x, "linear_srgb"))
    np.testing.assert_allclose(out.data, -np.sqrt(x), atol=1e-6)


def test_tone_sidd_is_smoothstep():
    x = np.linspace(-0.2, 1.2, 141)
    xc = np.clip(x, 0, 1)
    ref = 3 * xc ** 2 - 2 * xc ** 3
    out = Tone(curve="sidd")(_frame(np.tile(x[:, None, None], (1, 1, 3)), "display"))
    np.testing.assert_allclose(out.data[:, 0, 0], ref, atol=1e-6)
    assert out.kind == "display"


def test_tone_filmic_is_hable():
    # Hable (2010), "Filmic Tonemapping Operators": Uncharted2Tonemap with ExposureBias 2, its
    # white point W put at the scene white (1 by default) after exposure
    def u2(x):
        a, b, c, d, e, f = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30
        return ((x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f)) - e / f

    x = np.linspace(0, 8, 200)
    for ev in (0.0, 1.0, -1.5):
        for white in (1.0, 5.6):
            k = 2.0 * 2 ** ev
            ref = u2(k * x) / u2(k * white)
            out = Tone(curve="filmic", exposure=ev, white=white)(
                _frame(np.tile(x[:, None, None], (1, 1, 3)), "linear_srgb"))
            np.testing.assert_allclose(out.data[:, 0, 0], ref, atol=1e-5)
    # Hable's published normalisation: W = 11.2 at bias 2 is scene value 5.6
    np.testing.assert_allclose(disp.tone_filmic(x, 0.0, 5.6), u2(2.0 * x) / u2(11.2), atol=1e-5)


def test_tone_filmic_reaches_white():
    for ev in (-2.0, 0.0, 1.5):
        y = disp.tone_filmic(np.array([0.0, 1.0, 1e6]), ev)
        assert y[0] == pytest.approx(0.0, abs=1e-6) and y[1] == pytest.approx(1.0, abs=1e-6) and y[2] > 1.0
    assert np.all(np.diff(disp.tone_filmic(np.linspace(0, 8, 200))) > 0)


@pytest.mark.parametrize("curve", ["none", "sidd"])
def test_tone_exposure_acts_for_every_curve(curve):
    x = np.linspace(0.0, 0.6, 61)
    f = _frame(np.tile(x[:, None, None], (1, 1, 3)), "linear_srgb" if curve == "none" else "display")
    out = Tone(curve=curve, exposure=1.0)(f).data[:, 0, 0]
    g = 2.0 * x
    ref = g if curve == "none" else 3 * np.clip(g, 0, 1) ** 2 - 2 * np.clip(g, 0, 1) ** 3
    np.testing.assert_allclose(out, ref, atol=1e-6)


def test_tone_none_is_identity():
    f = _frame(np.random.default_rng(1).normal(size=(3, 3, 3)), "linear_srgb")
    assert np.array_equal(Tone()(f).data, f.data)
