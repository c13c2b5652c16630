"""The exposure-dependent and defect effects against closed forms.

dark_current / amp_glow: Poisson electrons, mean and variance rate * t (EMVA 1288 R4.0 sec. 4.2);
dead_pixels: exact fractions; adc_dnl: code occupancy of a uniform ramp equals the code widths;
rtn: two-level pixels with the drawn amplitude; charge_crosstalk: flat-field variance factor
(1 - 4c)^2 + 4c^2 and adjacent correlation, dark frames untouched. Tolerances: 5 standard errors.
"""

import numpy as np
import pytest

from simcam.errors import NoiseModelError
from simcam.noise import NoiseCondition, model_from_entry

E = 1e-3  # normalised raw per electron


def comp(effects, base=None, seed=0):
    base = base or {"type": "gaussian", "sigma": 1e-9}
    return model_from_entry({"type": "composite", "base": base, "effects": effects, "sensor_seed": seed})


def cond(t):
    return NoiseCondition(cfa="RGGB", exposure_s=t)


@pytest.mark.parametrize("t", [0.1, 2.0])
def test_dark_current_mean_and_variance_grow_linearly_with_exposure(t):
    m = comp([{"type": "dark_current", "rate": 40.0, "electron": E}])
    x = m.sample_frames(np.zeros((64, 64), np.float32), cond(t), np.random.default_rng(3), 16) / E  # electrons
    lam = 40.0 * t
    n = x.size
    assert abs(x.mean() - lam) < 5 * np.sqrt(lam / n)
    assert abs(x.var() - lam) < 5 * lam * np.sqrt(2 / n) + 5 * np.sqrt(lam / n)


def test_dark_current_dcnu_is_fixed_and_log_normal():
    s = 0.4
    m = comp([{"type": "dark_current", "rate": 100.0, "dcnu_log_sigma": s, "electron": E}])
    x = m.sample_frames(np.zeros((128, 128), np.float32), cond(10.0), np.random.default_rng(4), 8) / E
    rate = x.mean(0) / 10.0  # per-pixel temporal mean rate; Poisson noise var 1000/8 electrons^2 on the mean
    cv2_total = rate.var() / rate.mean() ** 2
    cv2_poisson = (100.0 * 10.0 / 8) / (100.0 * 10.0) ** 2
    assert np.sqrt(cv2_total - cv2_poisson) == pytest.approx(np.sqrt(np.exp(s * s) - 1), rel=0.05)
    assert rate.mean() == pytest.approx(100.0, rel=0.02)
    # the same sensor seed: the same map in another capture
    y = m.sample_frames(np.zeros((128, 128), np.float32), cond(10.0), np.random.default_rng(9), 8) / E
    assert np.corrcoef(x.mean(0).ravel(), y.mean(0).ravel())[0, 1] > 0.9


def test_dark_current_temperature_doubling():
    e = {"type": "dark_current", "rate": 10.0, "electron": E, "reference_temperature_c": 25.0, "doubling_c": 7.0}
    hot = comp([{**e, "temperature_c": 39.0}])
    x = hot.sample(np.zeros((256, 256), np.float32), cond(1.0), np.random.default_rng(5)) / E
    assert x.mean() == pytest.approx(40.0, rel=5 * np.sqrt(40.0 / x.size) / 40.0 + 1e-9)


def test_exposure_effects_need_the_exposure_time():
    m = comp([{"type": "dark_current", "rate": 10.0, "electron": E}])
    with pytest.raises(NoiseModelError, match="exposure"):
        m.sample(np.zeros((8, 8), np.float32), NoiseCondition(cfa="RGGB"), np.random.default_rng(0))


def test_amp_glow_profile_and_exposure_scaling():
    m = comp([{"type": "amp_glow", "rate": 500.0, "origin": "left", "scale": 0.25, "electron": E}])
    h, w = 32, 200
    x = m.sample_frames(np.zeros((h, w), np.float32), cond(2.0), np.random.default_rng(6), 32) / E
    col = x.mean((0, 1))
    expected = 500.0 * 2.0 * np.exp(-np.arange(w) / (0.25 * w))
    se = np.sqrt(expected / (32 * h))
    assert np.all(np.abs(col - expected) < 5 * se + 1e-9)


def test_dead_pixels_fractions_and_values():
    m = comp([{"type": "dead_pixels", "dead_fraction": 0.01, "stuck_fraction": 0.02, "stuck_value": 0.9}])
    x = m.sample(np.full((200, 200), 0.4, np.float32), cond(1.0), np.random.default_rng(0))
    n = x.size
    for frac, val in ((0.01, 0.0), (0.02, 0.9)):
        k = np.count_nonzero(x == np.float32(val))
        assert abs(k / n - frac) < 5 * np.sqrt(frac * (1 - frac) / n)


def test_dead_pixels_keeping_read_noise_read_black_plus_it():
    """dead_read_noise: no photo-response, the read noise kept (Poisson-Gaussian base, beta2 = read variance):
    the dead pixels' values over frames have mean 0 and variance beta2 (chi-square SE), the others the
    signal's; stuck pixels stay exact."""
    b1, b2 = 1e-3, 4e-6
    m = comp([{"type": "dead_pixels", "dead_fraction": 0.02, "stuck_fraction": 0.01, "stuck_value": 0.9,
               "dead_read_noise": True}], base={"type": "poisson_gaussian", "beta1": b1, "beta2": b2})
    x = m.sample_frames(np.full((96, 96), 0.4, np.float32), cond(1.0), np.random.default_rng(2), 24)
    fixed = m.fixed_patterns((96, 96))[0]
    dead = x.reshape(24, -1)[:, fixed["dead"]]
    n = dead.size
    assert abs(dead.mean()) < 5 * np.sqrt(b2 / n)
    assert dead.var() == pytest.approx(b2, abs=5 * b2 * np.sqrt(2 / n))
    assert np.all(x.reshape(24, -1)[:, fixed["stuck"]] == np.float32(0.9))
    assert x.mean() > 0.35  # the others respond


def test_hot_pixels_with_a_rate_grow_with_exposure_as_charge():
    """hot_rate: a hot pixel is offset_i + rate_i t of dark charge (Poisson, hot_electron per electron):
    over frames its mean is that (SE from the Poisson variance), the rates a log-normal of mean hot_rate;
    the map and the offsets are those of the profile without rates; without an exposure time it is an
    error."""
    e = {"type": "hot_pixels", "hot_fraction": 0.05, "hot_offset": 0.02, "hot_log_sigma": 0.3,
         "hot_electron": 1e-4, "hot_rate": 0.01, "hot_rate_log_sigma": 0.5}
    m = comp([e], base={"type": "gaussian", "sigma": 1e-12})
    no_rate = comp([{k: v for k, v in e.items() if not k.startswith("hot_rate")}], base={"type": "gaussian", "sigma": 1e-12})
    f, f0 = m.fixed_patterns((128, 128))[0], no_rate.fixed_patterns((128, 128))[0]
    assert np.array_equal(f["hot"], f0["hot"]) and np.array_equal(f["hot_offset"], f0["hot_offset"])
    assert m.to_entry()["effects"][0]["hot_rate"] == 0.01
    assert "hot_rate" not in no_rate.to_entry()["effects"][0]
    rate = f["hot_rate"].astype(np.float64)
    n = rate.size
    # log-normal of mean 0.01: the sample mean within 5 SE (SE = 0.01 sqrt(exp(0.25) - 1) / sqrt(n))
    assert rate.mean() == pytest.approx(0.01, abs=5 * 0.01 * np.sqrt(np.expm1(0.25) / n))
    for t in (0.5, 4.0):
        x = m.sample_frames(np.zeros((128, 128), np.float32), cond(t), np.random.default_rng(3), 16)
        hot = x.reshape(16, -1)[:, f["hot"]].astype(np.float64)
        expect = f["hot_offset"].astype(np.float64) + rate * np.float32(t)
        # Poisson charge: variance hot_electron * expect per value, 16 frames per pixel, summed over pixels
        se = np.sqrt(np.sum(1e-4 * expect) / 16) / n
        assert hot.mean() == pytest.approx(expect.mean(), abs=5 * se + 1e-6)
    with pytest.raises(NoiseModelError, match="exposure"):
        m.sample_frames(np.zeros((32, 32), np.float32), NoiseCondition(cfa="RGGB"), np.random.default_rng(0), 1)


def test_adc_dnl_code_occupancy_equals_code_widths():
    e = {"type": "adc_dnl", "range_dn": 255.0, "offset_dn": 0.0, "bits": 8, "dnl_sigma": 0.25}
    m = comp([e], base={"type": "gaussian", "sigma": 1e-12})
    ramp = np.linspace(0.5, 254.5, 2000 * 128, dtype=np.float64).reshape(2000, 128) / 255.0
    x = m.sample(ramp.astype(np.float32), cond(1.0), np.random.default_rng(0))
    codes = np.round(x.astype(np.float64) * 255.0).astype(int)
    counts = np.bincount(codes.ravel(), minlength=256)[2:254]
    edges = m.fixed_patterns((1, 1))[0]["edges"]
    widths = np.diff(edges)[1:253]  # code k spans [edges[k-1], edges[k])
    per_lsb = ramp.size / 254.0
    expected = widths * per_lsb
    assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected) + 2)
    assert widths.std() > 0.2  # unequal codes, DNL std ~ sqrt(2) * 0.25


def test_rtn_two_levels():
    m = comp([{"type": "rtn", "fraction": 0.05, "amplitude": 0.01, "p_high": 0.3}])
    x = m.sample_frames(np.zeros((64, 64), np.float32), cond(1.0), np.random.default_rng(1), 200)
    rtn = np.abs(x).max(0) > 0.005
    assert abs(rtn.mean() - 0.05) < 5 * np.sqrt(0.05 * 0.95 / rtn.size)
    high = (x[:, rtn] > 0.005).mean()
    assert abs(high - 0.3) < 5 * np.sqrt(0.3 * 0.7 / (200 * rtn.sum()))


def test_charge_crosstalk_flat_variance_drop_and_dark_untouched():
    c = 0.06
    base = {"type": "poisson_gaussian", "beta1": 1e-3, "beta2": 1e-8}
    m = comp([{"type": "charge_crosstalk", "coefficient": c}], base=base)
    flat = np.full((128, 128), 0.5, np.float32)
    x = m.sample_frames(flat, cond(1.0), np.random.default_rng(2), 16)
    d = x - x.mean(0)
    v = (d * d).sum(0).mean() / 15
    factor = (1 - 4 * c) ** 2 + 4 * c * c
    assert v == pytest.approx(1e-3 * 0.5 * factor + 1e-8, rel=0.03)
    r = (d[:, :, :-1] * d[:, :, 1:]).mean() / (d * d).mean()
    rho = 2 * c * (1 - 4 * c) / factor  # adjacent pixels share c of each other's charge
    assert r == pytest.approx(rho, abs=0.02)
    assert abs(x.mean() - 0.5) < 1e-3  # charge is conserved
    dark = m.sample_frames(np.zeros((128, 128), np.float32), cond(1.0), np.random.default_rng(3), 16)
    dd = dark - dark.mean(0)
    vd = (dd * dd).sum(0).mean() / 15  # read noise only: no electrons to share
    assert vd == pytest.approx(1e-8, rel=0.03)
    assert abs((dd[:, :, :-1] * dd[:, :, 1:]).mean() / (dd * dd).mean()) < 0.02


@pytest.mark.parametrize("signal", [0.0, 0.5])
def test_spatial_correlation_total_domain_couples_darks_and_flats_alike(signal):
    # electrical crosstalk after the pixel: shot and read noise both get the cross kernel's adjacent
    # correlation 2c(1 - 4c) / f (closed form), the variance and the mean are kept
    c = 0.08
    base = {"type": "poisson_gaussian", "beta1": 1e-3, "beta2": 2e-4}
    m = comp([{"type": "spatial_correlation", "coefficient": c, "neighbours": "adjacent", "domain": "total"}],
             base=base)
    x = m.sample_frames(np.full((128, 128), signal, np.float32), cond(1.0), np.random.default_rng(5), 16)
    d = x - x.mean(0)
    v = (d * d).sum(0).mean() / 15
    assert v == pytest.approx(1e-3 * signal + 2e-4, rel=0.03)
    factor = (1 - 4 * c) ** 2 + 4 * c * c
    r = (d[:, :, :-1] * d[:, :, 1:]).mean() / (d * d).mean()
    assert r == pytest.approx(2 * c * (1 - 4 * c) / factor, abs=0.015)
    assert abs(x.mean() - signal) < 1e-3


def test_spatial_correlation_total_domain_needs_adjacent_and_a_small_coefficient():
    with pytest.raises(NoiseModelError, match="domain 'total'"):
        comp([{"type": "spatial_correlation", "coefficient": 0.1, "domain": "total"}])
    with pytest.raises(NoiseModelError, match="domain 'total'"):
        comp([{"type": "spatial_correlation", "coefficient": 0.3, "neighbours": "adjacent", "domain": "total"}])
