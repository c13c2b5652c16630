"""Noise estimators recover known parameters on synthetic images of varied content.

Tolerances. NLF: each 512x512 mosaic gives 4 planes x 16,384 Haar blocks, minus
rejected ones (~50k samples). The sample variance of n zero-mean normal values
has relative standard error sqrt(2/n); spread over level sets and fitting two
parameters, the standard error of beta1 is ~1-2 % and that of sigma(y) at a
mid-range y below 1 %. Measured errors over these scenes and 3 NLFs were at
most 4.3 % (beta1) and 1.3 % (sigma(y)), the excess being estimator bias
(textures leaking through the smoothness test). We allow 10 % on beta1 and 4 %
on sigma(y) for y in {0.2, 0.6}: about 2-3x the worst bias seen, and > 4 SE.
Chen's sigma: 256x256 image, 64-D patches at stride 3 (~7,000 patches): the
eigenvalue mean has relative SE ~ 1/sqrt(#eigs * #patches) ~ 0.2 %; measured
errors <= 1.4 %; we allow 4 %.
"""

import numpy as np
import pytest
from scipy import integrate, ndimage, stats

from simcam.denoise.noise_estimation import clipped_moments, estimate_nlf, estimate_sigma
from simcam.errors import DatasetError


def scene(kind: str, n: int, rng) -> np.ndarray:
    yy, xx = np.mgrid[0:n, 0:n] / n
    if kind == "gradient":
        return 0.02 + 0.96 * (0.6 * xx + 0.4 * yy)
    if kind == "shapes":  # blurred discs of random intensity (edges of every orientation)
        img = np.full((n, n), 0.1)
        for _ in range(25):
            cy, cx, r = rng.random(3) * [n, n, n / 5]
            img[(yy * n - cy) ** 2 + (xx * n - cx) ** 2 < r * r] = rng.random()
        return ndimage.gaussian_filter(img, 1.5)
    if kind == "texture":
        return 0.5 + 0.45 * np.sin(2 * np.pi * 6 * xx) * np.cos(2 * np.pi * 4 * yy)
    if kind == "clipped":  # large regions at 0 and at 1
        return np.clip(-0.1 + 1.2 * xx, 0, 1)
    raise ValueError(kind)


def test_clipped_moments_match_numerical_integration():
    for y, s in [(0.5, 0.1), (0.01, 0.05), (0.98, 0.04), (-0.05, 0.02), (1.1, 0.3)]:
        def clipped(t):
            return np.clip(y + s * t, 0, 1)
        m = integrate.quad(lambda t: clipped(t) * stats.norm.pdf(t), -12, 12, points=[-y / s, (1 - y) / s])[0]
        m2 = integrate.quad(lambda t: clipped(t) ** 2 * stats.norm.pdf(t), -12, 12, points=[-y / s, (1 - y) / s])[0]
        mean, std = clipped_moments(np.array(y), np.array(s))
        assert mean == pytest.approx(m, abs=1e-9)
        assert std == pytest.approx(np.sqrt(m2 - m * m), rel=1e-6)


@pytest.mark.parametrize("kind", ["gradient", "shapes", "texture", "clipped"])
@pytest.mark.parametrize("beta", [(4e-3, 2e-5), (5e-4, 1e-6), (1e-2, 1e-4)])
def test_nlf_recovered(kind, beta):
    b1, b2 = beta
    rng = np.random.default_rng(12345)
    y = scene(kind, 512, rng)
    z = np.clip(y + np.sqrt(b1 * y + b2) * rng.standard_normal(y.shape), 0, 1)
    est = estimate_nlf(z)
    assert est.beta1 == pytest.approx(b1, rel=0.10)
    for level in (0.2, 0.6):
        assert est.sigma_at(level) == pytest.approx(np.sqrt(b1 * level + b2), rel=0.04)


def test_clipping_model_matters_and_per_plane():
    # Heavily clipped data: ignoring clipping (clip=None) must do clearly worse on beta1.
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:512, 0:512] / 512
    y = np.clip(-0.4 + 1.8 * xx, 0, 1)
    b1, b2 = 1e-2, 1e-4
    z = np.clip(y + np.sqrt(b1 * y + b2) * rng.standard_normal(y.shape), 0, 1)
    good = estimate_nlf(z, per_plane=True)
    naive = estimate_nlf(z, clip=None)
    assert abs(good.beta1 / b1 - 1) < 0.10
    assert abs(naive.beta1 / b1 - 1) > 2 * abs(good.beta1 / b1 - 1)
    assert good.planes.shape == (4, 2)
    np.testing.assert_allclose(good.planes[:, 0], b1, rtol=0.2)  # 1/4 of the data per plane


@pytest.mark.parametrize("kind", ["gradient", "shapes", "texture", "clipped"])
@pytest.mark.parametrize("sigma", [0.005, 0.02, 0.05])
def test_chen_sigma_recovered(kind, sigma):
    rng = np.random.default_rng(99)
    y = scene(kind, 256, rng)
    assert estimate_sigma(y + sigma * rng.standard_normal(y.shape)) == pytest.approx(sigma, rel=0.04)


def test_bad_shapes():
    with pytest.raises(DatasetError, match="shape"):
        estimate_nlf(np.zeros((3, 8, 8)))
    with pytest.raises(DatasetError, match="shape"):
        estimate_sigma(np.zeros((4, 4)))
