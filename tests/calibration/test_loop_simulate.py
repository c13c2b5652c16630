"""The loop's bootstrap is simcam's noise stage (no second simulator): moments of the simulated
capture against closed forms in DN."""

import numpy as np
import pytest

from simcam.calibration.model import LoopModel, SimSpec
from simcam.calibration.simulate import simulate_capture


def _model(**effects):
    m = LoopModel("RGGB", np.full((2, 2), 64.0), 1023.0, 2.0, 3.0, 0.0, effects=effects)
    m.var_dark_dn2 = 9.0 + m.q ** 2 / 12 + effects.get("row_noise", {}).get("sigma_dn", 0.0) ** 2
    m.refit_read()
    return m


def test_moments_of_the_simulated_capture():
    m = _model(row_noise={"sigma_dn": 1.5}, dsnu={"sigma_dn": 2.0}, black_level_offset={"offset_dn": [4.0] * 4})
    h = w = 64
    flat = np.full((h, w), 400.0)
    specs = [SimSpec("dark", 16, np.zeros((h, w))), SimSpec("flat", 16, flat)]
    dark, fl = simulate_capture(m, specs, np.random.default_rng(0))
    # integer ADC codes
    assert np.all(dark == np.round(dark)) and np.all(fl == np.round(fl))
    # dark mean = black + offset (SE ~ sqrt(2^2/4096 + ...) < 0.05 DN)
    assert dark.mean() == pytest.approx(68.0, abs=0.15)
    # temporal variance of a dark pixel = read^2 + row^2 + 1/12 = 9 + 2.25 + 1/12 (SE ~ 1 % -> 5 %)
    assert np.var(dark - dark.mean(0), axis=0, ddof=1).mean() == pytest.approx(11.33, rel=0.05)
    # row means: sigma_row^2 + (read^2 + 1/12)/W (1024 rows x frames, SE ~ 5 % -> 20 %)
    r = dark - dark.mean(0)
    assert np.var(r.mean(axis=2), axis=1, ddof=1).mean() * 16 / 15 == pytest.approx(2.25 + 9.08 / 64, rel=0.2)
    # DSNU: variance of the 16-frame mean map = dsnu^2 + temporal / 16 (SE ~ 3 % -> 12 %)
    assert np.var(dark.mean(0)) == pytest.approx(4.0 + 11.33 / 16, rel=0.12)
    # the same sensor in both sequences: the DSNU of the dark shows in the flat's mean map, correlation
    # 4 / sqrt((4 + 11.3/16) (4 + 811/16)) = 0.25 (0 for two sensors), SE 1/sqrt(4096) = 0.016
    assert np.corrcoef(dark.mean(0).ravel(), fl.mean(0).ravel())[0, 1] == pytest.approx(0.25, abs=0.08)
    # flat: shot-noise variance K * signal + dark temporal variance (SE ~ 1 % -> 5 %)
    v = np.var(fl - fl.mean(0), axis=0, ddof=1).mean()
    assert v == pytest.approx(2.0 * 400 + 11.33, rel=0.05)


def test_nonlinearity_bends_the_photon_transfer_curve():
    """y = x + c x^2 / S on the noisy value: measured mean y0 has var = (1 + 2 c x0 / S)^2 (K x0 + read^2) + 1/12,
    x0 the linear level (delta method; the exact Gaussian correction 2 c^2 v^2 / S^2 is < 0.01 DN^2 here).
    16 frames x 4096 pixels: SE of the variance ~ 1 % -> 5 %."""
    c, s = -0.12, 959.0
    m = _model(nonlinearity={"c": c})
    y0 = 600.0  # measured mean above black
    x0 = (np.sqrt(1 + 4 * c * y0 / s) - 1) * s / (2 * c)
    (fl,) = simulate_capture(m, [SimSpec("flat", 16, np.full((64, 64), y0))], np.random.default_rng(1))
    assert fl.mean() - 64.0 == pytest.approx(y0, abs=1.0)  # E y = y0 + c var / S (< 0.3 DN)
    v = np.var(fl - fl.mean(0), axis=0, ddof=1).mean()
    want = (1 + 2 * c * x0 / s) ** 2 * (2.0 * x0 + 9.0) + 1 / 12
    assert v == pytest.approx(want, rel=0.05)
    assert v < 0.85 * (2.0 * x0 + 9.0)  # far from the un-bent curve


def test_crosstalk_lag_correlations_in_darks():
    """spatial_correlation a: in-plane lag-1 2a / (1 + 2a^2), lag-2 a^2 / (1 + 2a^2) of the read noise, diluted
    by the 1/12 DN^2 quantisation noise (factor 9 / 9.083). SE of a correlation over 16 x 1024 x 2 pairs per
    plane, 4 planes: ~ 1.5 / sqrt(131072) = 0.004 (1.5: overlapping pairs) -> 0.02."""
    a = 0.35
    m = _model(spatial_correlation={"a": a})
    (dk,) = simulate_capture(m, [SimSpec("dark", 16, np.zeros((64, 64)))], np.random.default_rng(2))
    r = dk - dk.mean(0)
    dil = 9.0 / (9.0 + 1 / 12)
    for lag, want in ((1, 2 * a / (1 + 2 * a * a)), (2, a * a / (1 + 2 * a * a))):
        vals = []
        for dy, dx in ((0, 0), (0, 1), (1, 0), (1, 1)):
            p = r[:, dy::2, dx::2]
            vals.append(np.mean(p[:, :, lag:] * p[:, :, :-lag]) / np.mean(p * p))
        assert np.mean(vals) == pytest.approx(want * dil, abs=0.02)
    # variance kept: read^2 + 1/12 (SE 1 % -> 5 %)
    assert np.var(r, ddof=0) * 16 / 15 == pytest.approx(9.0 + 1 / 12, rel=0.05)


def test_hot_pixel_offsets_are_log_normal():
    """The loop's hot-pixel log-normal (log_mean, log_sigma, DN) is simulated with its spread: on a
    256x256 dark with fraction 0.02 (~1300 hot pixels) the 16-frame mean map minus black, at the hot
    pixels, has log mean ~ log_mean and log sd ~ log_sigma. The mean map's noise (sd 3 / 4 DN) on
    offsets of median e^4 = 55 DN shifts the logs by < 0.02 (1 % of the offsets at most); SE of the log
    mean s / sqrt(N) = 0.02, of the log sd s / sqrt(2N) = 0.014 -> 0.1 / 0.07 tolerance."""
    lm, ls = 4.0, 0.7
    m = _model(hot_pixels={"fraction": 0.02, "log_mean": lm, "log_sigma": ls})
    (dk,) = simulate_capture(m, [SimSpec("dark", 16, np.zeros((256, 256)))], np.random.default_rng(3))
    off = dk.mean(0) - 64.0
    hot = off > 6.0
    assert abs(hot.mean() - 0.02) < 5 * np.sqrt(0.02 * 0.98 / hot.size)
    lo = np.log(off[hot])
    assert lo.mean() == pytest.approx(lm, abs=0.1)
    assert lo.std() == pytest.approx(ls, abs=0.07)
