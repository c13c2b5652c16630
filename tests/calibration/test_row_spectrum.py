"""Coloured row noise: row offsets that wander from row to row (``empirical_spectrum``), told from white
row noise (``row_noise``) by the lag-1 autocorrelation of the dark row means and their spectrum.

The darks are made here with numpy (first-order autoregressive row offsets by ``scipy.signal.lfilter``),
not with simcam's noise code or the loop's generators; the expectations are closed forms: the AR(1)
spectrum ``sigma^2 (1 - rho^2) / (1 - 2 rho cos 2 pi f + rho^2)`` and its lag-1 autocorrelation ``rho``.
"""

import numpy as np
import pytest
from scipy.signal import lfilter

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, FitContext
from simcam.calibration.effects.empirical_spectrum import variance_dn2
from simcam.calibration.model import LoopModel

H, W, N = 256, 64, 16
READ, BLACK = 2.0, 64.0


def _darks(seed: int, white: float = 0.0, ar: float = 0.0, rho: float = 0.0) -> dg.CaptureData:
    rng = np.random.default_rng(seed)
    x = BLACK + rng.normal(0.0, READ, (N, H, W))
    if white:
        x += rng.normal(0.0, white, (N, H, 1))
    if ar:  # stationary AR(1) of variance ar^2 (200 rows of burn-in)
        kick = rng.normal(0.0, ar * np.sqrt(1 - rho * rho), (N, H + 200))
        x += lfilter([1.0], [1.0, -rho], kick, axis=1)[:, 200:, None]
    return dg.CaptureData([np.round(x)], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def _model(effects=None) -> LoopModel:
    return LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, 1.0, READ, READ ** 2 + 1 / 12, effects=effects or {})


def test_row_mean_lag1_is_zero_for_white_rows_and_rho_for_ar1_rows():
    # white: E = -1/(H - 1) (each frame's mean removed); SE ~ 1 / sqrt(N H) = 0.016 per capture, 0.005 over 10
    white = [dg.row_mean_lag1(_darks(s, white=1.5)) for s in range(10)]
    assert abs(np.mean(white) + 1 / (H - 1)) < 3 * 0.016 / np.sqrt(10)
    # AR(1), rho 0.6: the pixel noise's share of the row means' variance is (4 + 1/12) / 64 / (4 + 0.064) = 1.6 %,
    # the mean removal biases by about -(1 + rho) / ((1 - rho) H) = -0.016; SE sqrt((1 - rho^2) / (N H)) = 0.013
    ar = [dg.row_mean_lag1(_darks(s, ar=2.0, rho=0.6)) for s in range(10)]
    want = 0.6 * 4 / (4 + (READ ** 2 + 1 / 12) / W) - 1.6 / (0.4 * H)
    assert abs(np.mean(ar) - want) < 3 * 0.013 / np.sqrt(10) + 0.005


def _ar_spectrum(f, sigma, rho):
    return sigma ** 2 * (1 - rho * rho) / (1 - 2 * rho * np.cos(2 * np.pi * f) + rho * rho)


def test_card_measures_the_ar1_spectrum_and_its_variance():
    sigma, rho = 2.0, 0.7
    p = CARDS["empirical_spectrum"].fit(_darks(3, ar=sigma, rho=rho), _model(), FitContext())
    f, s = np.asarray(p.frequencies), np.asarray(p.power_dn2)
    assert f[0] == pytest.approx(1 / H) and f[-1] < 0.5 and np.all(np.diff(f) > 0)
    # each band averages N frames x its bins of exponential periodogram values: relative SE 1 / sqrt(N bins) <= 25 %;
    # the band's closed form is taken at its (geometric-mean) frequency, a second-order error inside a band
    want = _ar_spectrum(f, sigma, rho)
    assert np.all(np.abs(s / want - 1) < 4 * 0.25)
    assert np.median(np.abs(s / want - 1)) < 0.15
    # the offsets' variance: sigma^2 = 4 (the frame mean's share measured on the frames' means)
    assert variance_dn2(p) == pytest.approx(sigma ** 2, rel=0.12)
    # the power at f = 0: H x the variance of the frames' mean offsets, S(0) = sigma^2 (1 + rho) / (1 - rho) for
    # an AR(1) (H >> its correlation length); 16 frames per capture: relative SE sqrt(2 / 15) = 0.37, 6 captures
    dc = [CARDS["empirical_spectrum"].fit(_darks(s, ar=sigma, rho=rho), _model(), FitContext()).dc_power_dn2
          for s in range(10, 16)]
    assert np.mean(dc) == pytest.approx(sigma ** 2 * (1 + rho) / (1 - rho), rel=3 * 0.37 / np.sqrt(6))


def test_white_part_beside_the_coloured_one_is_left_to_row_noise():
    """White row noise (1.5 DN) beside AR(1) row offsets: the spectrum leaves the white part out and row_noise,
    refitted with the spectrum in the model, takes it."""
    d = _darks(5, white=1.5, ar=2.0, rho=0.9)
    spec = CARDS["empirical_spectrum"].fit(d, _model(), FitContext())
    coloured = variance_dn2(spec)
    assert coloured == pytest.approx(4.0, rel=0.3)
    total = CARDS["row_noise"].fit(d, _model(), FitContext()).sigma_dn ** 2
    assert total == pytest.approx(4.0 + 1.5 ** 2, rel=0.2)
    white = CARDS["row_noise"].fit(d, _model({"empirical_spectrum": spec}), FitContext()).sigma_dn
    assert white == pytest.approx(1.5, rel=0.2)
    assert white ** 2 + coloured == pytest.approx(total, rel=0.2)


def test_a_power_law_alone_keeps_no_white_part():
    """1/f row offsets (spectral synthesis with numpy: power f^-1.1 at every rfft bin, 0.5 DN^2 at f = 1/H):
    the spectrum holds them all, so row_noise refitted beside it is the identity."""
    rng = np.random.default_rng(9)
    f = np.fft.rfftfreq(H)
    amp = np.zeros(f.size)
    amp[1:] = np.sqrt(0.5 * (f[1:] * H) ** -1.1)
    rows = np.fft.irfft(np.fft.rfft(rng.normal(0.0, 1.0, (N, H)), axis=1) * amp, H, axis=1)
    x = BLACK + rng.normal(0.0, READ, (N, H, W)) + rows[:, :, None]
    d = dg.CaptureData([np.round(x)], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB")
    spec = CARDS["empirical_spectrum"].fit(d, _model(), FitContext())
    assert variance_dn2(spec) == pytest.approx(float(np.var(rows)), rel=0.2)
    assert CARDS["row_noise"].is_null(CARDS["row_noise"].fit(d, _model({"empirical_spectrum": spec}), FitContext()))


def test_white_row_noise_has_no_coloured_part():
    """White row offsets are row_noise's: the empirical component's fit is null and says why."""
    card = CARDS["empirical_spectrum"]
    p = card.fit(_darks(7, white=1.5), _model(), FitContext())
    assert card.is_null(p) and variance_dn2(p) == 0.0
    assert "spectrum is white" in card.null_reason(p) and "row_noise" in card.null_reason(p)


def test_noise_stage_draws_the_table_spectrum():
    """The noise effect's row offsets: their periodogram is the table, interpolated in log f (closed form), and
    their variance its mean over the frequencies (400 frames: relative SE 5 % per bin)."""
    from simcam.errors import NoiseModelError
    from simcam.noise.effects.base import effect_from_entry

    freqs, power = [1 / 128, 0.05, 0.2, 0.5], [1e-4, 2e-5, 4e-6, 1e-6]
    e = effect_from_entry({"type": "empirical_spectrum", "axis": "row", "frequencies": freqs, "power": power})
    rng = np.random.default_rng(0)
    n, frames = 128, 400
    y = np.stack([e.frame((n, 4), rng)["offset"][:, 0].astype(np.float64) for _ in range(frames)])
    per = (np.abs(np.fft.rfft(y, axis=1)) ** 2 / n).mean(0)
    k = np.array([1, 3, 6, 13, 25, 40, 64])
    want = np.interp(np.log(k / n), np.log(freqs), power)
    assert np.all(np.abs(per[k] / want - 1) < 4 * 0.05 * np.where(k == 64, np.sqrt(2), 1))
    full = np.concatenate(([power[0]], np.interp(np.log(np.abs(np.fft.fftfreq(n))[1:]), np.log(freqs), power)))
    assert y.var() == pytest.approx(full.mean(), rel=0.1)
    col = effect_from_entry({"type": "empirical_spectrum", "axis": "column", "frequencies": freqs, "power": power})
    assert col.frame((4, n), rng)["offset"].shape == (1, n)
    with pytest.raises(NoiseModelError, match="frequencies: expected increasing"):
        effect_from_entry({"type": "empirical_spectrum", "frequencies": [0.2, 0.1], "power": [1.0, 1.0]})
