"""Metrics equal scikit-image's (an independent implementation) on random pairs."""

import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from simcam.denoise.image_metrics import MetricError, psnr, ssim


def _pair(rng, shape, sigma):
    ref = rng.random(shape)
    return ref, ref + sigma * rng.standard_normal(shape)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_raw_mosaic_metrics_equal_skimage(seed):
    rng = np.random.default_rng(seed)
    ref, test = _pair(rng, (64, 48), 0.05 * (seed + 1))
    assert psnr(ref, test, data_range=1.0) == pytest.approx(
        peak_signal_noise_ratio(ref, test, data_range=1.0), rel=1e-12)
    want = structural_similarity(ref, test, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False)
    assert ssim(ref, test, data_range=1.0) == pytest.approx(want, abs=1e-12)
    assert ssim(ref, test, data_range=1.0, window="uniform") == pytest.approx(
        structural_similarity(ref, test, data_range=1.0), abs=1e-12)


@pytest.mark.parametrize("data_range", [1.0, 255.0])
def test_srgb_metrics_equal_skimage_channel_axis(data_range):
    rng = np.random.default_rng(7)
    ref, test = _pair(rng, (40, 36, 3), 0.1)
    ref, test = ref * data_range, test * data_range
    assert psnr(ref, test, data_range=data_range) == pytest.approx(
        peak_signal_noise_ratio(ref, test, data_range=data_range), rel=1e-12)
    want = structural_similarity(ref, test, data_range=data_range, channel_axis=-1, gaussian_weights=True,
                                 sigma=1.5, use_sample_covariance=False)
    assert ssim(ref, test, data_range=data_range, channel_axis=-1) == pytest.approx(want, abs=1e-12)


def test_float32_inputs_close_to_skimage():
    rng = np.random.default_rng(3)
    ref, test = (a.astype(np.float32) for a in _pair(rng, (32, 32), 0.02))
    want = structural_similarity(ref, test, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False)
    assert ssim(ref, test, data_range=1.0) == pytest.approx(want, abs=1e-5)


def test_identical_and_bad_inputs():
    x = np.linspace(0, 1, 400).reshape(20, 20)
    assert psnr(x, x, data_range=1.0) == float("inf")
    assert ssim(x, x, data_range=1.0) == pytest.approx(1.0)
    with pytest.raises(MetricError, match="shape"):
        psnr(x, x[:10], data_range=1.0)
    with pytest.raises(MetricError, match="data_range"):
        psnr(x, x, data_range=0.0)
