"""Defective pixels (Abdelhamed 2020, section 5.3.1) and intensity alignment (5.3.2)."""

import numpy as np
import pytest

from simcam.groundtruth.defects import (DefectMap, correct_defects, detect_defects_dark, detect_hot_flat,
                                                fit_gaussian_wls, load_defect_map, save_defect_map)
from simcam.groundtruth.intensity import align_intensity, frame_outliers
from simcam.errors import DatasetError


def test_wls_gaussian_fit_resists_outliers():
    rng = np.random.default_rng(0)
    v = np.concatenate([rng.normal(0.1, 0.01, 98000), rng.uniform(0.2, 1.0, 2000)])  # 2 % defects
    mu, sg = fit_gaussian_wls(v)
    # one-sided 2 % contamination moves the inliers' plotting positions by up to 2 %: the inlier
    # median sits at F = 0.49, z = -0.025, so a bias of ~0.03 sigma is inherent; allow 0.05 sigma
    assert abs(mu - 0.1) < 0.05 * 0.01 and abs(sg / 0.01 - 1) < 0.05
    assert v.std() > 5 * 0.01  # the plain estimate would be useless


def test_dark_detection_finds_hot_pixels_with_nominal_false_alarms():
    rng = np.random.default_rng(1)
    H, W = 400, 400
    mean = rng.normal(0.01, 0.001, (H, W)).astype(np.float32)
    hot = rng.random((H, W)) < 0.002
    mean[hot] += rng.uniform(0.006, 0.05, hot.sum())  # >= 6 sigma
    dm = detect_defects_dark(mean, "RGGB", confidence=0.999)
    assert dm.mask[hot].all()
    # false alarms: binomial(n, 1e-3): mean 160, sd 12.6; allow 4 sd
    fa = np.count_nonzero(dm.mask & ~hot)
    assert abs(fa - 0.001 * (H * W - hot.sum())) < 4 * np.sqrt(0.001 * H * W)
    assert len(dm.stats) == 4


def test_flat_detection_ignores_shading():
    rng = np.random.default_rng(2)
    H, W = 300, 400
    yy, xx = np.mgrid[0:H, 0:W]
    shade = 0.5 * (1 - 0.3 * ((yy - H / 2) ** 2 + (xx - W / 2) ** 2) / (H * W / 2))
    img = (shade + rng.normal(0, 0.002, (H, W))).astype(np.float32)
    dead = np.zeros((H, W), bool)
    dead[rng.integers(0, H, 30), rng.integers(0, W, 30)] = True
    img[dead] *= 0.5
    dm = detect_hot_flat(img, "RGGB")
    assert dm.mask[dead].all() and dm.count < dead.sum() + 0.003 * H * W


def test_correction_is_exact_for_cubic_planes_and_leaves_others():
    # per-plane cubic in x plus cubic in y: the row and column Lagrange cubics are exact
    H, W = 64, 80
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    img = (1e-6 * (yy ** 3 - 2 * xx ** 3) + 1e-4 * yy * 0 + 0.3 + 1e-3 * xx).astype(np.float32)
    img[1::2, 0::2] += 0.2  # a different colour plane level: interpolation must stay in-plane
    mask = np.zeros((H, W), bool)
    mask[20, 30] = mask[31, 41] = mask[40, 10] = True
    bad = img.copy()
    bad[mask] = 1.0
    out = correct_defects(bad, mask, "RGGB")
    np.testing.assert_allclose(out[mask], img[mask], rtol=0, atol=2e-5)
    np.testing.assert_array_equal(out[~mask], bad[~mask])
    assert bad[20, 30] == 1.0  # input untouched


def test_correction_fills_clusters():
    rng = np.random.default_rng(3)
    img = np.full((40, 40), 0.5, np.float32) + rng.normal(0, 1e-3, (40, 40)).astype(np.float32)
    mask = np.zeros_like(img, bool)
    mask[10:18, 10:18] = True
    out = correct_defects(np.where(mask, 1.0, img), mask, "RGGB")
    assert np.abs(out[mask] - 0.5).max() < 0.01


def test_defect_map_roundtrip_and_sidd(tmp_path, shared_file):
    dm = DefectMap(np.eye(6, dtype=bool), "t", [{"plane": [0, 0], "mu": 0.1}])
    p = save_defect_map(tmp_path / "d.npz", dm)
    back = load_defect_map(p, (6, 6))
    np.testing.assert_array_equal(back.mask, dm.mask)
    assert back.stats == dm.stats
    with pytest.raises(DatasetError, match="shape"):
        load_defect_map(p, (5, 6))
    sidd = load_defect_map(shared_file("sidd/DefectivePixelsMask_GP_4048x3044.mat"))
    assert sidd.mask.shape == (3044, 4048) and sidd.count == 59358


def test_intensity_outliers_and_eq_5_4():
    rng = np.random.default_rng(4)
    means = 0.4 + 1e-3 * rng.standard_normal(30)
    means[7] = 0.36  # 40 sigma darker (flicker)
    io = frame_outliers(means)
    assert list(np.nonzero(~io.keep)[0]) == [7]
    assert io.mu_a == pytest.approx(np.delete(means, 7).mean())
    # with few frames the dissertation's plain mean/std can never flag one outlier: z <= (N-1)/sqrt(N) = 2.85
    few = np.array([0.4, 0.401, 0.399, 0.4005, 0.3995, 0.4002, 0.3998, 0.4001, 0.3999, 0.2])
    assert not (~frame_outliers(few, robust=False).keep).any()
    assert (~frame_outliers(few).keep).sum() == 1
    x = rng.random((4, 4)).astype(np.float32)
    np.testing.assert_allclose(align_intensity(x, 0.3, 0.5), x + 0.2, atol=1e-6)
    np.testing.assert_allclose(align_intensity(x, 0.25, 0.5, "multiplicative"), 2 * x, atol=1e-6)
