"""PRNU is a gain: the same relative spread at every signal level (EMVA 1288 Release 4.0, sec. 8.2).

A per-pixel non-linearity -- each pixel's response ``e (1 - c_p e / FW)`` curving by its own amount
(floating-diffusion capacitances that differ) -- also makes a fixed pattern in flats, but one whose
relative spread grows with the signal. The ``prnu`` card measures the relative spread on two flats
(:func:`simcam.calibration.diagnostics.prnu_by_level`, jackknife standard errors over bands of rows):
where it grows significantly and no level-independent part is left, the fit is null.

The flats are made here with numpy, not with simcam's noise code or the loop's generators.
"""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, FitContext
from simcam.calibration.effects.prnu import LEVEL_Z, spread_growth
from simcam.calibration.model import LoopModel

H, W, N = 128, 128, 8
K, READ, BLACK, FULL_E = 0.5, 2.0, 64.0, 12000.0
LEVELS_E = (1800.0, 6600.0)  # 15 % and 55 % of the full well


def _capture(seed: int, prnu: float, pixel_nl: float) -> dg.CaptureData:
    rng = np.random.default_rng(seed)
    gain = 1 + rng.normal(0.0, prnu, (H, W))
    c = np.abs(rng.normal(0.0, pixel_nl, (H, W)))
    flats = []
    for s in LEVELS_E:
        e = rng.poisson(np.broadcast_to(s * gain, (N, H, W))).astype(np.float64)
        e = e * (1 - c * e / FULL_E)
        flats.append(np.round(BLACK + K * e + rng.normal(0.0, READ, (N, H, W))))
    dark = np.round(BLACK + rng.normal(0.0, READ, (N, H, W)))
    return dg.CaptureData([dark], flats, [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def _model() -> LoopModel:
    return LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, K, READ, READ ** 2 + 1 / 12)


def _fit(d):
    return CARDS["prnu"].fit(d, _model(), FitContext())


def test_relative_spread_is_level_independent_for_a_gain_and_its_z_is_standard_normal():
    zs = []
    for seed in range(24):
        g = spread_growth(_capture(seed, 0.01, 0.0), 0.0, 4095.0 - BLACK)
        zs.append(g[1])
    zs = np.asarray(zs)
    # 24 draws: the mean of standard normals is within 3 / sqrt(24) = 0.61 of 0, their SD within
    # ~ +-0.45 of 1 (chi-square, 23 dof, 3-sigma)
    assert abs(zs.mean()) < 0.61
    assert 0.55 < zs.std(ddof=1) < 1.45
    assert zs.max() < LEVEL_Z


def test_gain_alone_keeps_the_brightest_flats_estimate():
    p = _fit(_capture(1, 0.01, 0.0))
    assert p.spread_growth is None
    assert p.sigma == pytest.approx(0.01, rel=0.05)


def test_a_per_pixel_nonlinearity_is_not_a_gain():
    d = _capture(2, 0.0, 0.03)
    ratio, z, icpt, se, _slope = spread_growth(d, 0.0, 4095.0 - BLACK)
    # relative deviation c_p e / FW grows as the signal: ratio of spreads = 6600 / 1800 = 3.7
    assert ratio == pytest.approx(LEVELS_E[1] / LEVELS_E[0], rel=0.15)
    assert z > LEVEL_Z
    p = _fit(d)
    assert CARDS["prnu"].is_null(p)
    assert "grows with the signal" in CARDS["prnu"].null_reason(p)


def test_gain_beside_a_per_pixel_nonlinearity_is_kept():
    p = _fit(_capture(3, 0.01, 0.03))
    # relative variances 1e-4 + (0.603 x 0.03 x 0.15)^2 and 1e-4 + (0.603 x 0.03 x 0.55)^2 (c_p half-normal):
    # spreads 1.036 % and 1.407 %, ratio 1.36
    assert p.spread_growth == pytest.approx(1.36, rel=0.08)
    _, _, icpt, se, _slope = spread_growth(_capture(3, 0.01, 0.03), 0.0, 4095.0 - BLACK)
    # the intercept of v(L) = sigma^2 + k L^2 through two points is the PRNU's variance (1e-4)
    assert icpt == pytest.approx(1e-4, abs=3 * se)
    # the card keeps the brightest flat's estimate: the PRNU and the growing part at 55 % (1.407 %)
    assert p.sigma == pytest.approx(0.01407, rel=0.08)
