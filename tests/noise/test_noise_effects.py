"""Physical effects: variances from theory, persistence across frames, Tukey-lambda quantiles."""

import numpy as np
import pytest
from scipy import stats

from simcam.noise import NoiseCondition, model_from_entry
from simcam.noise.effects import EFFECT_NAMES, effect_from_entry, effect_types

COND = NoiseCondition(cfa="RGGB", exposure_s=0.5)
B2 = 1e-6  # base read variance used below

EXAMPLES = {
    "row_noise": {"sigma": 2e-3},
    "column_fpn": {"sigma": 2e-3},
    "dsnu": {"sigma": 2e-3},
    "prnu": {"sigma": 0.02},
    "hot_pixels": {"hot_fraction": 0.01, "stuck_fraction": 0.005, "dead_fraction": 0.002},
    "heavy_tail_read": {"lam": -0.1, "scale": 1e-3},
    "quantization": {"range_dn": 1023.0},
    "spatial_correlation": {"coefficient": 0.1},
    "periodic_pattern": {"amplitude": 1e-3, "period_px": 8.0},
    "black_level_offset": {"offset": [1e-3, 0.0, 0.0, -1e-3]},
    "frame_flicker": {"sigma": 0.01},
    "nonlinearity": {"strength": 0.02},
    "channel_gain": {"gain": [1.0, 1.02, 0.98, 1.0]},
    "dark_current": {"rate": 50.0, "dcnu_log_sigma": 0.3, "electron": 1e-3},
    "amp_glow": {"rate": 200.0, "origin": "top_right", "scale": 0.2, "electron": 1e-3},
    "dead_pixels": {"dead_fraction": 0.01, "stuck_fraction": 0.005},
    "adc_dnl": {"range_dn": 1023.0, "offset_dn": 64.0, "bits": 10, "dnl_sigma": 0.3},
    "rtn": {"fraction": 0.02, "amplitude": 5e-3, "amplitude_log_sigma": 0.3},
    "charge_crosstalk": {"coefficient": 0.05},
    "empirical_offset": {"axis": "column", "quantiles": [-2e-3, -1e-3, 0.0, 1e-3, 3e-3]},
    "empirical_gain": {"axis": "pixel", "quantiles": [0.97, 0.99, 1.0, 1.01, 1.03]},
    "empirical_lines": {"axis": "column", "lines": [[0.25, 2e-3]]},
    "empirical_spectrum": {"axis": "row", "frequencies": [0.02, 0.1, 0.5], "power": [1e-5, 2e-6, 1e-6]},
    "empirical_code": {"range_dn": 1023.0, "offset_dn": 64.0, "edges": [float(k) + 0.5 for k in range(1100)]},
    "empirical_field": {"field": [[1e-3, 2e-3], [3e-3, 4e-3]], "electron": 1e-3},
    "empirical_response": {"quantiles": [-0.01, 0.0, 0.02, 0.05, 0.12]},
}


def _comp(effects, base=None, seed=0):
    base = base or {"type": "gaussian", "sigma": float(np.sqrt(B2))}
    return model_from_entry({"type": "composite", "base": base, "effects": effects, "sensor_seed": seed})


def test_registry_has_every_documented_name():
    assert set(effect_types()) == set(EFFECT_NAMES) == set(EXAMPLES)


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_effect_round_trip_and_runs(name):
    e = effect_from_entry({"type": name, **EXAMPLES[name]})
    assert effect_from_entry(e.to_entry()) == e
    m = _comp([e.to_entry()])
    clean = np.full((40, 36), 0.3, np.float32)
    a = m.sample(clean, COND, np.random.default_rng(1))
    b = m.sample(clean, COND, np.random.default_rng(1), chunk_rows=7)
    assert a.tobytes() == b.tobytes() and a.dtype == np.float32


def test_row_noise_row_mean_variance():
    """Dark frame: row means have var sigma_r^2 + B2 / W.

    SE of a sample variance of n normal values: var * sqrt(2 / (n - 1)); 5 SE.
    """
    s = 2e-3
    h, w = 2000, 64
    x = _comp([{"type": "row_noise", "sigma": s}]).sample(np.zeros((h, w), np.float32), COND, np.random.default_rng(2))
    v = x.mean(axis=1).var(ddof=1)
    th = s * s + B2 / w
    assert abs(v - th) < 5 * th * np.sqrt(2 / (h - 1))


def test_column_fpn_column_mean_variance_and_persistence():
    s = 2e-3
    h, w = 64, 2000
    m = _comp([{"type": "column_fpn", "sigma": s}], seed=7)
    f1 = m.sample(np.zeros((h, w), np.float32), COND, np.random.default_rng(1))
    f2 = m.sample(np.zeros((h, w), np.float32), COND, np.random.default_rng(2))
    c1, c2 = f1.mean(axis=0), f2.mean(axis=0)
    th = s * s + B2 / h
    assert abs(c1.var(ddof=1) - th) < 5 * th * np.sqrt(2 / (w - 1))
    # persistence: the column pattern is shared, the temporal part is not:
    # cov(c1, c2) = s^2 (SE as above), and frames differ
    cov = np.cov(c1, c2)[0, 1]
    assert abs(cov - s * s) < 5 * th * np.sqrt(2 / (w - 1))
    assert not np.array_equal(f1, f2)
    # another sensor seed: a different pattern (correlation ~ 0, SE 1/sqrt(w))
    g = _comp([{"type": "column_fpn", "sigma": s}], seed=8).sample(np.zeros((h, w), np.float32), COND, np.random.default_rng(1))
    assert abs(np.corrcoef(c1, g.mean(axis=0))[0, 1]) < 5 / np.sqrt(w)


def test_dsnu_temporal_mean_variance():
    """T frames: per-pixel temporal means have var sigma_d^2 + B2 / T across pixels."""
    s, t = 2e-3, 16
    m = _comp([{"type": "dsnu", "sigma": s}], seed=3)
    frames = np.stack([m.sample(np.zeros((64, 64), np.float32), COND, np.random.default_rng(i)) for i in range(t)])
    tm = frames.mean(axis=0)
    n = tm.size
    th = s * s + B2 / t
    assert abs(tm.var(ddof=1) - th) < 5 * th * np.sqrt(2 / (n - 1))


def test_prnu_temporal_mean_variance():
    """Flat signal mu, NLF base: temporal-mean var = (sigma_p mu)^2 + (b1 mu + b2) / T (E[gain] = 1)."""
    sp, mu, t, b1, b2 = 0.02, 0.5, 16, 1e-4, 1e-6
    m = _comp([{"type": "prnu", "sigma": sp}], base={"type": "nlf", "beta1": b1, "beta2": b2}, seed=4)
    clean = np.full((64, 64), mu, np.float32)
    frames = np.stack([m.sample(clean, COND, np.random.default_rng(i)) for i in range(t)])
    tm = frames.mean(axis=0)
    th = (sp * mu) ** 2 + (b1 * mu + b2) / t
    assert abs(tm.mean() - mu) < 5 * np.sqrt(th / tm.size)
    assert abs(tm.var(ddof=1) - th) < 5 * th * np.sqrt(2 / (tm.size - 1))


def test_tukey_lambda_quantiles_match_scipy():
    """Empirical quantiles of scale * TL(lam) vs scipy.stats.tukeylambda.ppf.

    SE of the p-quantile of n draws: sqrt(p (1 - p) / n) / f(q) (asymptotic
    normality of sample quantiles), f the scipy density; 5 SE.
    """
    lam, scale, n = -0.15, 1e-3, 200_000
    m = _comp([{"type": "heavy_tail_read", "lam": lam, "scale": scale}], base={"type": "gaussian", "sigma": 0.0})
    x = m.sample(np.zeros((400, 500), np.float32), COND, np.random.default_rng(8)).ravel().astype(np.float64)
    dist = stats.tukeylambda(lam, scale=scale)
    for p in (0.001, 0.01, 0.1, 0.5, 0.9, 0.99, 0.999):
        q = dist.ppf(p)
        se = np.sqrt(p * (1 - p) / n) / dist.pdf(q)
        assert abs(np.quantile(x, p) - q) < 5 * se, p


def test_hot_pixel_fractions_and_persistence():
    e = {"type": "hot_pixels", "hot_fraction": 0.01, "hot_offset": 0.2, "stuck_fraction": 0.005,
         "stuck_value": 1.0, "dead_fraction": 0.002}
    m = _comp([e], base={"type": "gaussian", "sigma": 0.0}, seed=5)
    clean = np.full((200, 200), 0.3, np.float32)
    a = m.sample(clean, COND, np.random.default_rng(1))
    b = m.sample(clean, COND, np.random.default_rng(2))
    n = a.size
    for val, frac in ((0.5, 0.01), (1.0, 0.005), (0.0, 0.002)):
        cnt = np.isclose(a, val).sum()
        # binomial count: SE = sqrt(n p (1-p))
        assert abs(cnt - n * frac) < 5 * np.sqrt(n * frac * (1 - frac)), val
    assert np.array_equal(a, b)  # no temporal noise: the defect map is fixed


def test_spatial_correlation_same_colour_neighbours():
    """Separable in-plane [c, 1, c] kernel, variance-preserving (closed form, effects/correlation.py):
    same-colour lag 1 (2 px): 2c / (1 + 2c^2); lag 2 (4 px): c^2 / (1 + 2c^2); diagonal (2, 2): lag1^2;
    different-colour neighbours (1 px): 0; variance unchanged.

    Sample correlation SE ~ (1 - r^2) / sqrt(n) for independent pairs; the pairs overlap (the field is
    correlated), which inflates it by at most sqrt(sum over 2-D lags of rho^2) (Bartlett); separable, so
    sum = (1 + 2 rho1^2 + 2 rho2^2)^2 = 2.33 for c = 0.3 -> factor 1.53, 5 SE x 1.6.
    """
    c = 0.3
    m = _comp([{"type": "spatial_correlation", "coefficient": c}], base={"type": "gaussian", "sigma": 0.01})
    x = m.sample(np.zeros((300, 300), np.float32), COND, np.random.default_rng(3))[4:-4, 4:-4].astype(np.float64)
    n = x[:, 4:].size
    r1 = 2 * c / (1 + 2 * c * c)

    def corr(a, b):
        return np.corrcoef(a.ravel(), b.ravel())[0, 1]

    for got, want in ((corr(x[:, :-2], x[:, 2:]), r1), (corr(x[:-2], x[2:]), r1),
                      (corr(x[:, :-4], x[:, 4:]), c * c / (1 + 2 * c * c)),
                      (corr(x[:-2, :-2], x[2:, 2:]), r1 * r1),
                      (corr(x[:, :-1], x[:, 1:]), 0.0), (corr(x[:-1], x[1:]), 0.0)):
        assert abs(got - want) < 5 * 1.6 * (1 - want * want) / np.sqrt(n), (got, want)
    # variance of the sample variance of a correlated Gaussian field: 2 v^2 (sum of rho^2 = 2.33) / n; 5 SE
    assert abs(x.var() - 1e-4) < 5 * 1e-4 * np.sqrt(2 * 2.33 / n)


def test_spatial_correlation_acts_on_read_noise_only():
    """Read noise (beta2) is coupled, shot noise stays white, the mean is not blurred:
    lag-1 correlation = rho1 * beta2 / (beta1 clean + beta2), variance beta1 clean + beta2 (kept)."""
    c, b1, b2 = 0.3, 1e-3, 2e-4
    m = _comp([{"type": "spatial_correlation", "coefficient": c}], base={"type": "poisson_gaussian", "beta1": b1, "beta2": b2})
    clean = np.full((256, 256), 0.2, np.float32)
    clean[:, 128:] = 0.6  # an edge: the mean must stay sharp
    x = m.sample_frames(clean, COND, np.random.default_rng(4), 24).astype(np.float64)
    mean = x.mean(0)
    # column means of 24 frames x 256 rows: SE sqrt(8e-4 / 6144) ~ 3.6e-4, x sqrt(1 + 2 rho1 + 2 rho2) = 1.43
    # for the correlated column -> 5 SE x 1.5
    assert abs(mean[:, 125].mean() - 0.2) < 5 * 1.5 * 3.6e-4 and abs(mean[:, 130].mean() - 0.6) < 5 * 1.5 * 3.6e-4
    r = x[:, 4:-4, 132:-4] - 0.6
    n = r[:, :, 2:].size
    got = np.corrcoef(r[:, :, :-2].ravel(), r[:, :, 2:].ravel())[0, 1]
    want = 2 * c / (1 + 2 * c * c) * b2 / (b1 * 0.6 + b2)
    assert abs(got - want) < 5 * 1.6 / np.sqrt(n)  # SE as above
    assert abs(r.var() / (b1 * 0.6 + b2) - 1) < 5 * np.sqrt(2 * 2.33 / r.size)  # variance (PTC) kept
    # frame by frame (sample) gives the same law: lag-1 correlation of one frame, SE 1.6 / sqrt(n / 24)
    one = m.sample(clean, COND, np.random.default_rng(5)).astype(np.float64)[4:-4, 132:-4] - 0.6
    got1 = np.corrcoef(one[:, :-2].ravel(), one[:, 2:].ravel())[0, 1]
    assert abs(got1 - want) < 5 * 1.6 / np.sqrt(one[:, 2:].size)


def test_spatial_correlation_needs_a_read_noise_part():
    from simcam.errors import NoiseModelError

    # a clipped base has no separable read noise (clipping acts on shot + read together)
    with pytest.raises(NoiseModelError, match="read noise"):
        _comp([{"type": "spatial_correlation", "coefficient": 0.2}],
              base={"type": "clipped", "base": {"type": "gaussian", "sigma": 0.01}}).sample(
            np.zeros((8, 8), np.float32), COND, np.random.default_rng(0))


def test_nonlinearity_acts_on_the_noisy_value():
    """y = x - s x^2 on x ~ N(mu, v): E y = mu - s (mu^2 + v), var y = (1 - 2 s mu)^2 v + 2 s^2 v^2 (exact).

    SEs over N pixels: mean sqrt(var / N), variance var sqrt(2 / (N - 1)) (near-normal y); 5 SE.
    """
    s, mu, sd = 0.3, 0.7, 0.05
    m = _comp([{"type": "nonlinearity", "strength": s}], base={"type": "gaussian", "sigma": sd})
    y = m.sample_frames(np.full((200, 200), mu, np.float32), COND, np.random.default_rng(5), 8).astype(np.float64).ravel()
    v = sd * sd
    ev = mu - s * (mu * mu + v)
    vv = (1 - 2 * s * mu) ** 2 * v + 2 * s * s * v * v
    assert abs(y.mean() - ev) < 5 * np.sqrt(vv / y.size)
    assert abs(y.var(ddof=1) - vv) < 5 * vv * np.sqrt(2 / (y.size - 1))
    # an expected-signal-only compression would leave var y = v: 0.58^2 v is far from it
    assert y.var() < 0.5 * v


def test_nonlinearity_log_prob_is_a_density():
    """Change of variables: exp(log_prob) integrates to 1 and its mean is mu - s (mu^2 + v) (quadrature)."""
    s, mu, sd = 0.3, 0.5, 0.05
    m = _comp([{"type": "dsnu", "sigma": 0.0}, {"type": "nonlinearity", "strength": s},
               {"type": "black_level_offset", "offset": 0.01}], base={"type": "gaussian", "sigma": sd})
    grid = np.linspace(0.0, 0.8, 4001, dtype=np.float64)
    y = grid.astype(np.float32)
    p = np.exp(m.log_prob(y[None, :].repeat(2, 0), np.full((2, y.size), mu, np.float32), COND)[0])
    assert np.trapezoid(p, y) == pytest.approx(1.0, abs=1e-4)
    assert np.trapezoid(p * y, y) == pytest.approx(mu - s * (mu * mu + sd * sd) + 0.01, abs=1e-4)


def test_sample_frames_matches_sample_in_law_and_fixed_pattern():
    """sample_frames: the same fixed pattern as sample() (same sensor seed), temporal variance beta1 clean + beta2."""
    m = _comp([{"type": "dsnu", "sigma": 0.01}], base={"type": "poisson_gaussian", "beta1": 1e-3, "beta2": 1e-5}, seed=3)
    clean = np.full((64, 64), 0.3, np.float32)
    x = m.sample_frames(clean, COND, np.random.default_rng(0), 40).astype(np.float64)
    one = m.sample(clean, COND, np.random.default_rng(1)).astype(np.float64)
    off = m.fixed_patterns(clean.shape)[0]["offset"]
    # temporal mean over 40 frames: offset + clean, SE sqrt(3.1e-4 / 40) = 2.8e-3 per pixel -> max over 4096 < 5 SE
    assert np.abs(x.mean(0) - clean - off).max() < 5 * np.sqrt(3.1e-4 / 40)
    assert np.corrcoef((one - clean).ravel(), off.ravel())[0, 1] > 0.4  # dsnu var 1e-4 vs temporal 3.1e-4
    v = x.var(0, ddof=1).mean()
    assert abs(v - 3.1e-4) < 5 * 3.1e-4 * np.sqrt(2 / (39 * 4096))
    assert x.dtype == np.float64 and m.sample_frames(clean, COND, np.random.default_rng(0), 40).dtype == np.float32
    np.testing.assert_array_equal(m.sample_frames(clean, COND, np.random.default_rng(0), 3),
                                  m.sample_frames(clean, COND, np.random.default_rng(0), 3))


def test_deterministic_effects_exact_values():
    clean = np.full((4, 4), 0.5, np.float32)
    zero = {"type": "gaussian", "sigma": 0.0}
    g = _comp([{"type": "channel_gain", "gain": [1.0, 2.0, 0.5, 1.0]}], base=zero).sample(clean, COND, np.random.default_rng(0))
    np.testing.assert_allclose(g[:2, :2], [[0.5, 1.0], [0.25, 0.5]])
    nl = _comp([{"type": "nonlinearity", "strength": 0.1}], base=zero).sample(clean, COND, np.random.default_rng(0))
    np.testing.assert_allclose(nl, 0.5 - 0.1 * 0.25, rtol=1e-6)
    q = _comp([{"type": "quantization", "range_dn": 10.0, "step_dn": 2.0}], base=zero).sample(
        np.full((2, 2), 0.33, np.float32), COND, np.random.default_rng(0))
    np.testing.assert_allclose(q, 0.4)  # 3.3 DN -> 4 DN with a 2-DN step
    bl = _comp([{"type": "black_level_offset", "offset": [0.01, 0.0, 0.0, -0.01]}], base=zero).sample(
        clean, COND, np.random.default_rng(0))
    np.testing.assert_allclose(bl[:2, :2], [[0.51, 0.5], [0.5, 0.49]], rtol=1e-6)
    pp = _comp([{"type": "periodic_pattern", "amplitude": 0.01, "period_px": 4.0, "random_phase": False}], base=zero).sample(
        clean, COND, np.random.default_rng(0))
    np.testing.assert_allclose(pp[:, 0], 0.5 + 0.01 * np.sin(2 * np.pi * np.arange(4) / 4), atol=1e-7)


def test_frame_flicker_frame_mean_variance():
    """Frame means over K frames: var = (sigma_f mu)^2 + var(base)/N; 5 SE (normal)."""
    sf, mu, k = 0.01, 0.5, 200
    m = _comp([{"type": "frame_flicker", "sigma": sf}])
    means = np.array([m.sample(np.full((8, 8), mu, np.float32), COND, np.random.default_rng(i)).mean() for i in range(k)])
    th = (sf * mu) ** 2 + B2 / 64
    assert abs(means.var(ddof=1) - th) < 5 * th * np.sqrt(2 / (k - 1))


def test_composite_log_prob_given_fixed_pattern():
    """DSNU + PRNU composite: log_prob = NLF log_prob at the patterned signal, shifted by the offset."""
    m = _comp([{"type": "prnu", "sigma": 0.02}, {"type": "dsnu", "sigma": 1e-3}],
              base={"type": "nlf", "beta1": 1e-3, "beta2": 1e-5}, seed=9)
    clean = np.random.default_rng(0).random((8, 8), dtype=np.float32)
    noisy = m.sample(clean, COND, np.random.default_rng(1))
    fixed = m.fixed_patterns(clean.shape)
    sig = clean.astype(np.float64) * fixed[0]["gain"]
    ref = stats.norm.logpdf(noisy - fixed[1]["offset"], sig, np.sqrt(1e-3 * sig + 1e-5))
    np.testing.assert_allclose(m.log_prob(noisy, clean, COND), ref, rtol=1e-4, atol=1e-4)
    from simcam.errors import NoiseModelError

    with pytest.raises(NoiseModelError, match="row_noise"):
        _comp([{"type": "row_noise", "sigma": 1e-3}]).log_prob(noisy, clean, COND)


def test_hot_pixel_log_normal_offsets_match_closed_form_moments():
    """hot_log_sigma = s > 0: offsets o = m exp(s n - s^2/2), n ~ N(0, 1), i.e. log o ~ N(ln m - s^2/2, s^2)
    and E[o] = m (closed form). With N hot pixels (binomial, ~8000 here): SE of the mean of log o is
    s / sqrt(N), of the sample variance of log o s^2 sqrt(2 / (N - 1)), of the mean of o
    m sqrt(exp(s^2) - 1) / sqrt(N); 5 SE each. The distribution as a whole: KS test against scipy's lognorm."""
    m_off, s = 0.1, 0.6
    base = {"type": "gaussian", "sigma": 0.0}
    e = {"type": "hot_pixels", "hot_fraction": 0.05, "hot_offset": m_off, "hot_log_sigma": s}
    m = _comp([e], base=base, seed=11)
    clean = np.zeros((400, 400), np.float32)
    a = m.sample(clean, COND, np.random.default_rng(1)).astype(np.float64)
    o = a[a > 0]
    n = o.size
    assert abs(n - a.size * 0.05) < 5 * np.sqrt(a.size * 0.05 * 0.95)
    lo = np.log(o)
    assert abs(lo.mean() - (np.log(m_off) - s * s / 2)) < 5 * s / np.sqrt(n)
    assert abs(lo.var(ddof=1) - s * s) < 5 * s * s * np.sqrt(2 / (n - 1))
    assert abs(o.mean() - m_off) < 5 * m_off * np.sqrt(np.exp(s * s) - 1) / np.sqrt(n)
    assert stats.kstest(o, stats.lognorm(s, scale=m_off * np.exp(-s * s / 2)).cdf).pvalue > 1e-3
    # the same pixels are hot as with a constant offset, the pattern persists across frames, and
    # hot_log_sigma = 0 is today's constant offset, byte for byte
    const = _comp([dict(e, hot_log_sigma=0.0)], base=base, seed=11).sample(clean, COND, np.random.default_rng(1))
    old = _comp([{k: v for k, v in e.items() if k != "hot_log_sigma"}], base=base, seed=11).sample(
        clean, COND, np.random.default_rng(1))
    assert np.array_equal(const, old) and np.array_equal(const > 0, a > 0)
    assert np.array_equal(m.sample(clean, COND, np.random.default_rng(2)), a.astype(np.float32))
    with pytest.raises(Exception, match="hot_log_sigma"):
        effect_from_entry(dict(e, hot_log_sigma=-0.1))
