"""Robust per-pixel mean (Abdelhamed 2020, eq. 5.6-5.12): references are scipy optimisers and closed forms."""

import numpy as np
import pytest
from scipy import optimize, special, stats

from simcam.groundtruth.robust_mean import (censored_mle, plain_mean, robust_mean, wls_cdf_fit,
                                                    wls_objective)
from simcam.errors import DatasetError


def _burst(mu, sd, n, rng, lo=0.0, hi=1.0):
    x = mu + sd * rng.standard_normal((n,) + np.shape(mu))
    return np.clip(x, lo, hi).astype(np.float32)


def test_wls_matches_nelder_mead_on_eq_5_10():
    # reference: scipy's Nelder-Mead on the objective of Abdelhamed 2020, eq. 5.10, pixel by pixel (what the SIDD code does)
    rng = np.random.default_rng(1)
    mu = np.array([0.005, 0.3, 0.97, 0.99, 0.012, 0.6])
    x = _burst(mu, 0.02, 40, rng)
    r = wls_cdf_fit(x, refine=8)
    for j in range(mu.size):
        f = lambda p: wls_objective(p[0], p[1], x[:, j])  # noqa: E731
        o = optimize.minimize(f, [float(np.mean(x[:, j])), 0.02], method="Nelder-Mead",
                              options=dict(xatol=1e-10, fatol=1e-16, maxiter=5000))
        assert f([r.mu[j], r.sigma[j]]) <= o.fun * (1 + 1e-6) + 1e-12
        assert abs(r.mu[j] - o.x[0]) < 1e-5 and abs(r.sigma[j] - o.x[1]) < 1e-5


def test_closed_form_is_close_to_exact_minimiser():
    # the linearised closed form differs from the exact eq. 5.10 minimiser by a small fraction of the
    # standard error sigma/sqrt(N) = 0.02/sqrt(40) = 3.2e-3
    rng = np.random.default_rng(2)
    mu = rng.uniform(-0.01, 1.01, 3000)
    x = _burst(mu, 0.02, 40, rng)
    a, b = wls_cdf_fit(x, refine=0), wls_cdf_fit(x, refine=6)
    ok = a.valid
    assert np.sqrt(np.mean((a.mu[ok] - b.mu[ok]) ** 2)) < 0.15 * 0.02 / np.sqrt(40)


def test_censored_mle_reaches_scipy_likelihood():
    # reference: scipy.stats.norm.fit on CensoredData; our Newton solution must be at least as likely
    rng = np.random.default_rng(3)
    mu = np.array([0.004, 0.02, 0.5, 0.985, 0.995])
    x = _burst(mu, 0.015, 30, rng).astype(np.float64)
    r = censored_mle(x)

    def ll(m, s, v):
        u = v[(v > 0) & (v < 1)]
        return (stats.norm.logpdf(u, m, s).sum() + np.sum(v <= 0) * stats.norm.logcdf(0, m, s)
                + np.sum(v >= 1) * stats.norm.logsf(1, m, s))

    for j in range(mu.size):
        v = x[:, j]
        cd = stats.CensoredData(uncensored=v[(v > 0) & (v < 1)], left=v[v <= 0], right=v[v >= 1])
        m0, s0 = stats.norm.fit(cd)
        assert ll(r.mu[j], r.sigma[j], v) >= ll(m0, s0, v) - 1e-6
        assert abs(r.mu[j] - m0) < 0.05 * 0.015 / np.sqrt(30)


def test_censoring_bias_removed_and_plain_mean_bias_matches_closed_form():
    # truth mu = 0.01, sigma = 0.01: 16 % of the samples clip at 0.
    # E[max(X, 0)] = mu Phi(mu/s) + s phi(mu/s) (closed form) is what the plain mean converges to.
    rng = np.random.default_rng(4)
    P, N, m, s = 20000, 40, 0.01, 0.01
    x = _burst(np.full(P, m), s, N, rng)
    expect_plain = m * special.ndtr(m / s) + s * stats.norm.pdf(m / s)
    pm = plain_mean(x)
    se_pm = pm.mu.std() / np.sqrt(P)
    assert abs(pm.mu.mean() - expect_plain) < 4 * se_pm
    for est in (wls_cdf_fit(x), censored_mle(x)):
        se = est.mu.std() / np.sqrt(P)  # standard error of the average estimate
        assert abs(est.mu.mean() - m) < 4 * se + 2e-5  # 2e-5: O(1/N) small-sample bias allowance
        assert abs(pm.mu.mean() - m) > 50 * se  # the plain mean is clearly biased


def test_efficiency_and_sigma_on_uncensored_data():
    # for Gaussian samples the WLS L-estimator loses little against the mean (variance ratio ~1.06
    # measured; 1.2 allows for the Monte-Carlo error of a variance estimate from 20000 pixels, ~2 %)
    rng = np.random.default_rng(5)
    P, N = 20000, 30
    x = _burst(np.full(P, 0.5), 0.02, N, rng)
    w, pm = wls_cdf_fit(x), plain_mean(x)
    assert np.var(w.mu) / np.var(pm.mu) < 1.2
    assert abs(np.median(w.sigma) / 0.02 - 1) < 0.03
    assert abs(np.median(pm.sigma) / 0.02 - 1) < 0.03


def test_layouts_and_methods_agree():
    rng = np.random.default_rng(6)
    x = _burst(rng.uniform(0, 1, 500), 0.03, 25, rng)
    for meth in ("wls", "mle", "mean"):
        a = robust_mean(x, meth)
        b = robust_mean(np.ascontiguousarray(x.T), meth, axis=1)
        np.testing.assert_array_equal(a.mu, b.mu)


def test_fallbacks_and_missing_samples():
    x = np.array([[1.0, 0.0, 0.5, np.nan, 0.2],
                  [1.0, 0.0, 1.0, np.nan, 0.3],
                  [1.0, 0.0, 0.6, np.nan, np.nan],
                  [1.0, 0.0, 1.0, np.nan, 0.25]], dtype=np.float32)
    for meth in ("wls", "mle"):
        r = robust_mean(x, meth)
        assert r.mu[0] == 1.0 and not r.valid[0]          # all high-censored -> hi (a lower bound)
        assert r.mu[1] == 0.0 and not r.valid[1]          # all low-censored -> lo
        assert not r.valid[2] and 0.5 < r.mu[2] < 1.0     # 2 uncensored -> clipped plain mean
        assert np.isnan(r.mu[3]) and not r.valid[3]       # nothing finite
        assert r.valid[4] and r.n_used[4] == 3            # NaN is a missing sample, not a censored one
    with pytest.raises(DatasetError):
        robust_mean(x, "median")


def test_uncensored_mean_hybrid():
    rng = np.random.default_rng(7)
    x = _burst(rng.uniform(0, 1, 2000), 0.02, 20, rng)
    h = robust_mean(x, "wls", uncensored_mean=True)
    w, pm = wls_cdf_fit(x), plain_mean(x)
    cens = ((x <= 0) | (x >= 1)).any(0)
    assert cens.any() and (~cens).any()
    np.testing.assert_array_equal(h.mu[~cens], pm.mu[~cens])
    np.testing.assert_array_equal(h.mu[cens], w.mu[cens])


def test_known_nlf_wls_on_censored_pixels_near_oracle():
    # truths within ~3 sigma of the low clip: up to half the samples clip. Reference: the plain mean
    # of the same samples before clipping (the oracle). Measured MSE ratios: WLS 1.13, WLS with the
    # known NLF 1.07, censored MLE 1.07 (20k censored pixels: ratio SE ~ 1.5 %).
    rng = np.random.default_rng(8)
    N, P, b1 = 50, 40000, 1e-3
    mu = rng.uniform(0, 0.02, P)
    sd = np.sqrt(b1 * mu + b1 / 100)
    raw = (mu + sd * rng.standard_normal((N, P))).astype(np.float32)
    x = np.clip(raw, 0, 1)
    w, wn = wls_cdf_fit(x), wls_cdf_fit(x, nlf=(b1, b1 / 100))
    ok = (x <= 0).any(0) & w.valid
    mse = lambda e: np.mean((e - mu)[ok] ** 2)  # noqa: E731
    oracle = mse(raw.mean(0))
    assert mse(w.mu) < 1.2 * oracle
    assert mse(wn.mu) < mse(w.mu) and mse(wn.mu) < 1.12 * oracle
    np.testing.assert_allclose(wn.sigma[ok], np.sqrt(b1 * np.clip(wn.mu[ok], 0, None) + b1 / 100), rtol=1e-5)
