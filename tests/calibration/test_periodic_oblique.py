"""Oblique periodic patterns: the noise stage's tilted bands (closed-form spectrum), the 2-D spectrum
diagnostic and the periodic_pattern card's 2-D fit on frames drawn here with numpy (not by the loop's
simulator)."""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects.periodic_pattern import fit_oblique
from simcam.noise import NoiseCondition, model_from_entry


def _darks(wave=None, n=16, h=192, w=256, sigma=2.0, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    frames = 256.0 + sigma * rng.standard_normal((n, h, w))
    if wave is not None:
        amp, fy, fx = wave
        for f in range(n):
            frames[f] += amp * np.sin(2 * np.pi * (fy * y + fx * x) + rng.uniform(0, 2 * np.pi))
    return dg.CaptureData([frames.astype(np.float32)], [], [], None, 4095.0, "RGGB")


def test_noise_stage_tilted_bands_have_their_wave_vector():
    m = model_from_entry({"type": "composite", "base": {"type": "gaussian", "sigma": 1e-9}, "sensor_seed": 0,
                          "effects": [{"type": "periodic_pattern", "amplitude": 0.01, "period_px": 16.0,
                                       "axis": "rows", "cross_frequency": -3 / 128}]})
    x = m.sample_frames(np.zeros((128, 128), np.float32), NoiseCondition(cfa="RGGB"), np.random.default_rng(1), 2)
    p = np.abs(np.fft.fft2(x[0])) ** 2
    iy, ix = np.unravel_index(np.argmax(p), p.shape)
    # sin(2 pi (y / 16 - 3 x / 128)): lines at (ky, kx) = +-(8, -3) of 128
    assert {(iy, ix), ((-iy) % 128, (-ix) % 128)} == {(8, 125), (120, 3)}
    assert np.sqrt(2 * np.mean(x[0] ** 2)) == pytest.approx(0.01, rel=1e-3)


def test_frame_spectrum_peak_sees_an_oblique_wave_that_line_means_do_not():
    white = _darks(seed=2)
    wave = _darks((0.6, 1 / 13.0, 1 / 21.0), seed=2)
    # a normal score: about N(0, 1) on white noise (its law is checked in the next test), far out for a line
    assert abs(dg.frame_spectrum_peak(white)) < 4
    assert 15 < dg.frame_spectrum_peak(wave) < np.inf  # finite however strong the line (the loop drops non-finite values)
    # the row and column means average a wave at this angle away: their spectra barely move
    assert dg.row_spectrum_peak(wave) < 2 * dg.row_spectrum_peak(white) + 5


def test_frame_spectrum_peak_is_about_normal_on_white_noise():
    # the raw peak-over-median of many bins has a Gumbel tail (skew ~1.1); the normal score has little skew,
    # so the loop's t predictive law does not read the tail as a pattern (6 frames of 64 x 64: 99.9th
    # percentile of the raw ratio 1.7 x its median). 200 sets: SE of the skewness ~0.17.
    from scipy import stats

    rng = np.random.default_rng(9)
    v = np.array([dg.frame_spectrum_peak(dg.CaptureData([rng.standard_normal((6, 64, 64)).astype(np.float32)], [], [],
                                                        None, 1023.0, "RGGB")) for _ in range(200)])
    assert abs(stats.skew(v)) < 0.6
    assert 0.5 < v.std() < 1.5


@pytest.mark.parametrize("wave", [(0.6, 1 / 13.0, 1 / 21.0), (1.5, 1 / 30.0, -1 / 9.0), (0.8, 1 / 7.0, 1 / 60.0)])
def test_fit_oblique_recovers_the_wave(wave):
    amp, fy, fx = wave
    p = fit_oblique(_darks(wave, seed=3))
    if p.axis == "row":
        got_fy, got_fx = 1 / p.period_px, p.cross_frequency
    else:
        got_fx, got_fy = 1 / p.period_px, p.cross_frequency
    if np.sign(got_fy) != np.sign(fy):  # the same wave with the opposite wave vector
        got_fy, got_fx = -got_fy, -got_fx
    assert got_fy == pytest.approx(fy, abs=1 / (8 * 128) + 1e-9)
    assert got_fx == pytest.approx(fx, abs=1 / (8 * 128) + 1e-9)
    # amplitude: the projection over a 128 x 128 block has SE ~ sigma * 2 / 128 per frame and block
    assert p.amplitude_dn == pytest.approx(amp, rel=0.06)
    assert p.axis == ("row" if abs(fy) >= abs(fx) else "col")


def test_small_frames_are_not_applicable():
    d = _darks(h=24, w=24)
    with pytest.raises(dg.NotApplicable, match="32 x 32"):
        dg.frame_spectrum_peak(d)
    assert dg.statistic("frame_spectrum_peak", d)[0] is None


def test_row_noise_that_differs_between_cfa_columns_is_not_a_2d_peak():
    # per-frame row offsets, different on even and odd columns (a CFA's two colours of a row): energy on the
    # kx = 0 and kx = 1/2 lines only, which the 2-D spectrum leaves to the 1-D diagnostics
    rng = np.random.default_rng(4)
    d = _darks(seed=4)
    f = d.darks[0].astype(np.float64)
    off = rng.standard_normal((f.shape[0], f.shape[1], 2)) * np.array([1.5, 0.5])
    f[:, :, 0::2] += off[:, :, :1]
    f[:, :, 1::2] += off[:, :, 1:]
    rows = dg.CaptureData([f.astype(np.float32)], [], [], None, 4095.0, "RGGB")
    assert dg.row_mean_excess(rows) > 5
    assert dg.frame_spectrum_peak(rows) < 4
