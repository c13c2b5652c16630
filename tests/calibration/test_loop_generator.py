"""The test-owned generator against closed-form moments (it must be right for the loop tests to mean anything)."""

import numpy as np
from scipy import stats

from loop_generator import DEFAULT_EFFECTS, HiddenEffectSensor, SensorSpec, _tukey, _tukey_var


def test_poisson_gaussian_variance_matches_theory():
    # var(DN) = K^2 * mu_e + read^2 + 1/12 (rounding); 64*64*16 = 65536 values:
    # SE of a sample variance is var*sqrt(2/N) ~ 0.55 % -> 3 % tolerance is > 5 SE.
    spec = SensorSpec(height=64, width=64)
    s = HiddenEffectSensor(spec)
    f = s.frames(100.0, 16, np.random.default_rng(0)).astype(np.float64)
    want = spec.K ** 2 * 100 + spec.read_dn ** 2 + 1 / 12
    assert abs(f.var() / want - 1) < 0.03
    assert abs(f.mean() - (spec.black_dn + spec.K * 100)) < 0.1


def test_row_noise_row_mean_variance():
    # row means of a dark frame: var = sigma_row^2 + (read^2 + 1/12) / W; 64 rows x 64 frames,
    # SE of the variance ~ var * sqrt(2/4096) = 2.2 % -> 10 % tolerance.
    spec = SensorSpec(effects={"row_noise": {"sigma_dn": 2.0}})
    f = HiddenEffectSensor(spec).frames(0.0, 64, np.random.default_rng(1)).astype(np.float64)
    rm = f.mean(axis=2)
    want = 4.0 + (spec.read_dn ** 2 + 1 / 12) / spec.width
    assert abs(np.var(rm, axis=1, ddof=1).mean() / want - 1) < 0.10


def test_tukey_sampler_matches_scipy():
    x = _tukey(-0.2, 200_000, np.random.default_rng(2))
    assert stats.kstest(x, stats.tukeylambda(-0.2).cdf).pvalue > 0.001
    assert abs(_tukey_var(-0.2) / stats.tukeylambda(-0.2).var() - 1) < 1e-9


def test_fixed_patterns_persist_across_frames():
    spec = SensorSpec(effects={"dsnu": DEFAULT_EFFECTS["dsnu"]})
    s = HiddenEffectSensor(spec)
    a = s.frames(0.0, 8, np.random.default_rng(3)).mean(0)
    b = s.frames(0.0, 8, np.random.default_rng(4)).mean(0)
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.7


def test_hot_pixel_log_normal_fit_on_exponential_offsets():
    """The loop's log-normal fit (the hot_pixels card's fit) on the generator's exponential offsets (mean
    60 DN): it sees the offsets above its threshold t (6 robust sigma of the dark-mean map, ~8 DN here).
    Exponential, memoryless: detected fraction f exp(-t / 60), their mean t + 60 (closed forms; the map
    noise, sd ~ 1.3 DN, shifts the detected set by < 2 %). ~0.02 x 16384 x 0.87 = 290 detected pixels:
    SE of the count 17 (binomial), of the mean 68 / sqrt(290) = 4 DN -> 15 % / 15 % tolerances; the
    log-normal's mean exp(mu + s^2 / 2) is a different estimator of the same mean (5 % bias measured on
    1e5 exponential draws) -> 20 %."""
    import numpy as np
    import pytest

    from simcam.calibration import diagnostics as dg
    from simcam.calibration.effects import CARDS, FitContext
    from loop_generator import HiddenEffectSensor, SensorSpec

    spec = SensorSpec(height=128, width=128, effects={"hot_pixels": {"fraction": 0.02, "mean_dn": 60.0}})
    frames = HiddenEffectSensor(spec).frames(0.0, 12, np.random.default_rng(4))
    d = dg.CaptureData([frames], [], [], np.full((2, 2), spec.black_dn), spec.white_dn, spec.cfa)
    p = CARDS["hot_pixels"].fit(d, None, FitContext())
    m = d.dark_map()[0]
    t = 6 * dg.robust_sigma(dg.remove_profiles(m))
    assert p.fraction == pytest.approx(0.02 * np.exp(-t / 60.0), rel=0.15)
    assert np.exp(p.log_mean + p.log_sigma ** 2 / 2) == pytest.approx(t + 60.0, rel=0.2)
    # log sd of an exponential above t: ~1.1 for t / 60 ~ 0.13 (Var log X = pi^2 / 6 untruncated)
    assert 0.7 < p.log_sigma < 1.3
