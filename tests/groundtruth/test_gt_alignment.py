"""Dense local alignment (Abdelhamed 2020, section 5.3.3): references are scikit-image, scipy.ndimage.shift and closed forms."""

import numpy as np
import pytest
from scipy import ndimage

from simcam.groundtruth.alignment import (dense_field, local_shifts, ncc_threshold, patch_grid,
                                                  phase_correlation, prepare_reference, reject_outliers, warp)
from simcam.groundtruth.synthetic_burst import SyntheticBurst


def _texture(rng, n=320, smooth=1.5):
    img = ndimage.gaussian_filter(rng.standard_normal((n, n)), smooth)
    return img / img.std()


def test_phase_correlation_known_shift_and_skimage():
    skreg = pytest.importorskip("skimage.registration")
    rng = np.random.default_rng(0)
    for _ in range(5):
        img = _texture(rng)
        d = rng.uniform(-4, 4, 2)
        mov = ndimage.shift(img, d, order=3, mode="reflect")  # mov(p) = img(p - d)
        a = img[32:288, 32:288] + 0.1 * rng.standard_normal((256, 256))
        b = mov[32:288, 32:288] + 0.1 * rng.standard_normal((256, 256))
        s, ncc = phase_correlation(a, b)
        assert np.abs(s - d).max() < 0.05  # accuracy measured ~0.005-0.02 px at this noise level
        # skimage returns the shift that registers mov onto ref, i.e. -d, on a 1/20 px grid
        sk, _, _ = skreg.phase_cross_correlation(a, b, upsample_factor=20, normalization=None)
        assert np.abs(s + sk).max() < 0.06
        assert ncc > ncc_threshold(256, 256)


def test_ncc_threshold_rejects_pure_noise():
    # false-alarm rate of the extreme-value bound: expect well below 1 % on independent noise patches
    rng = np.random.default_rng(1)
    a = rng.standard_normal((200, 64, 64))
    b = rng.standard_normal((200, 64, 64))
    _, ncc = phase_correlation(a, b)
    assert np.mean(ncc > ncc_threshold(64, 64)) <= 0.01


def test_tps_field_reproduces_affine_field_exactly():
    # a thin-plate spline with its degree-1 polynomial part reproduces affine functions exactly
    H, W = 400, 600
    ys, xs = np.meshgrid(np.linspace(50, 350, 4), np.linspace(50, 550, 5), indexing="ij")
    lm = np.stack([ys.ravel(), xs.ravel()], 1)
    A = np.array([[0.002, -0.001], [0.0015, 0.003]])
    sh = lm @ A.T + np.array([0.3, -0.7])
    f = dense_field(lm, sh, (H, W), "RGGB")
    yy = np.arange(f.shape[1]) * 2 + 0.5
    xx = np.arange(f.shape[2]) * 2 + 0.5
    Y, X = np.meshgrid(yy, xx, indexing="ij")
    ref = np.stack([A[0, 0] * Y + A[0, 1] * X + 0.3, A[1, 0] * Y + A[1, 1] * X - 0.7])
    assert np.abs(f - ref).max() < 2e-4


def test_warp_matches_scipy_shift_per_plane():
    rng = np.random.default_rng(2)
    img = ndimage.gaussian_filter(rng.standard_normal((128, 160)), 3).astype(np.float32)
    field = np.zeros((2, 64, 80), np.float32)
    field[0], field[1] = 0.8, -1.4  # mosaic px = 0.4, -0.7 plane px
    out = warp(img, field, "RGGB", order=3)
    for dy, dx in ((0, 0), (0, 1), (1, 0), (1, 1)):
        ref = ndimage.shift(img[dy::2, dx::2], (-0.4, 0.7), order=3, mode="nearest")
        np.testing.assert_allclose(out[dy::2, dx::2][4:-4, 4:-4], ref[4:-4, 4:-4], atol=1e-5)


def test_local_shifts_recover_synthetic_drift():
    sb = SyntheticBurst(shape=(512, 512), n=5, drift_px=4.0, beta1=1e-4, beta2=1e-6, seed=3)
    ref = sb.frame(2)
    R = prepare_reference(ref, "RGGB")
    lm, sh, ok = local_shifts(R, sb.frame(4))
    keep = reject_outliers(R.grid, sh, ok)
    true = sb.drift(4, lm[:, 0], lm[:, 1]) - sb.drift(2, lm[:, 0], lm[:, 1])
    err = np.abs(sh[keep] - true.T[keep])
    assert keep.sum() >= 0.8 * len(lm)
    assert np.median(err) < 0.05 and err.max() < 0.2


def test_patch_grid_follows_seed_and_scales_down():
    g = patch_grid((3000, 4000), "RGGB")
    assert g.size * g.step == 512 and g.stride * g.step == 256 and g.xs[-1] + g.size == 2000
    small = patch_grid((200, 300), "RGGB")
    assert small.size <= 50 and len(small.ys) >= 2
    mono = patch_grid((480, 640), None)
    assert mono.step == 1 and mono.size == 128
