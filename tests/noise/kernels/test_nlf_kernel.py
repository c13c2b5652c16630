"""Fused NLF kernel: its normals against scipy's normal law, its moments against closed forms."""

import numpy as np
import pytest
from scipy import stats

from simcam.noise.kernels.nlf import nlf_noise

N = 2_000_000


def _normals(seed=0, n=N):
    return nlf_noise(np.zeros(n, np.float32), 0.0, 1.0, np.random.default_rng(seed), clip=None)


def test_normals_follow_the_standard_normal_law():
    z = _normals().astype(np.float64)
    # SE of the mean 1/sqrt(N) = 7.1e-4, of the variance sqrt(2/N) = 1.0e-3: 5 SE
    assert abs(z.mean()) < 5 / np.sqrt(N)
    assert abs(z.var() - 1) < 5 * np.sqrt(2 / N)
    # excess kurtosis SE sqrt(24/N) = 3.5e-3
    assert abs(stats.kurtosis(z)) < 5 * np.sqrt(24 / N)
    assert stats.kstest(z[:500_000], "norm").pvalue > 1e-3
    # binned chi-square over 40 equiprobable bins, and the tails beyond 3 and 4 sigma (the ziggurat's
    # tail and wedge rejections): counts within 5 binomial SE of N p
    edges = stats.norm.ppf(np.linspace(0, 1, 41))
    counts = np.histogram(z, edges)[0]
    assert stats.chisquare(counts).pvalue > 1e-3
    for t in (3.0, 4.0):
        p = 2 * stats.norm.sf(t)
        k = np.count_nonzero(np.abs(z) > t)
        assert abs(k - N * p) < 5 * np.sqrt(N * p * (1 - p))


def test_heteroscedastic_variance_and_clipping_match_closed_forms():
    b1, b2 = 4e-3, 2e-4
    for y in (0.02, 0.3):
        x = np.full(N // 4, y, np.float32)
        d = nlf_noise(x, b1, b2, np.random.default_rng(1), clip=None).astype(np.float64) - y
        var = b1 * y + b2  # Abdelhamed 2020, eq. 5.2
        assert d.var() == pytest.approx(var, rel=5 * np.sqrt(2 / d.size))
    # clipped at 0 (eq. 5.3): E[max(y + s z, 0)] = y Phi(y/s) + s phi(y/s)
    y, s = 0.01, np.sqrt(b1 * 0.01 + b2)
    x = np.full(N // 4, y, np.float32)
    out = nlf_noise(x, b1, b2, np.random.default_rng(2)).astype(np.float64)
    assert out.min() >= 0.0 and out.max() <= 1.0
    mean = y * stats.norm.cdf(y / s) + s * stats.norm.pdf(y / s)
    assert out.mean() == pytest.approx(mean, abs=5 * out.std() / np.sqrt(out.size))
    assert np.mean(out == 0.0) == pytest.approx(stats.norm.cdf(-y / s), abs=5 * np.sqrt(0.25 / out.size))


def test_deterministic_in_place_and_shape_kept():
    x = np.random.default_rng(3).random((4, 33, 17), dtype=np.float32)
    a = nlf_noise(x, 1e-3, 1e-5, np.random.default_rng(7))
    b = nlf_noise(x, 1e-3, 1e-5, np.random.default_rng(7))
    assert a.shape == x.shape and a.dtype == np.float32 and np.array_equal(a, b)
    y = x.copy()
    nlf_noise(y, 1e-3, 1e-5, np.random.default_rng(7), out=y)
    assert np.array_equal(y, a)
    assert not np.array_equal(a, nlf_noise(x, 1e-3, 1e-5, np.random.default_rng(8)))
    with pytest.raises(ValueError, match="C-contiguous float32"):
        nlf_noise(x, 1e-3, 1e-5, np.random.default_rng(7), out=np.empty(x.shape, np.float64))


@pytest.mark.parametrize("p", [1, 5, 64])
def test_packed_variant_equals_pack_then_noise(p):
    from simcam.cfa import pack
    from simcam.noise.kernels.nlf import nlf_noise_packed

    src = np.random.default_rng(0).random((300, 310), dtype=np.float32)
    crop = src[3:3 + 2 * p, 7:7 + 2 * p]  # a strided view, odd offsets
    clean = np.ascontiguousarray(pack(crop))
    noisy = nlf_noise(clean, 1e-2, 1e-4, np.random.default_rng(5))
    c2, n2 = np.empty((4, p, p), np.float32), np.empty((4, p, p), np.float32)
    nlf_noise_packed(crop, 1e-2, 1e-4, np.random.default_rng(5), c2, n2)
    assert np.array_equal(clean, c2) and np.array_equal(noisy, n2)
