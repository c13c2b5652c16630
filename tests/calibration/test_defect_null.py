"""The closed-form count of defect pixels a defect-free model makes (``diagnostics.defect_null_count``) and
the count law that takes it where every replicate counts 0: two stuck pixels in 16 k are a certain defect
(they were 'not significant' with 12 replicates' Jeffreys law: p ~ 0.005 among ~30 statistics)."""

import numpy as np
import pytest
from scipy import stats

from simcam.calibration import diagnostics as dg

BLACK, WHITE, READ, K = 64.0, 4095.0, 1.2, 0.5


def _capture(seed=0, size=128, n=8, level_e=4000.0, prnu=0.01, stuck=(), response=None):
    """Numpy darks and a flat (RGGB, 12-bit): read noise READ DN, shot noise at K DN/e-, a Gaussian PRNU;
    ``stuck`` pixels read one code in every frame; ``response`` overrides the per-pixel mean signal (DN)."""
    rng = np.random.default_rng(seed)
    sig = K * level_e * (1 + prnu * rng.standard_normal((size, size))) if response is None else response
    darks = np.round(BLACK + rng.normal(0, READ, (n, size, size)))
    flat = np.round(BLACK + sig + rng.normal(0, 1, (n, size, size)) * np.sqrt(K * np.maximum(sig, 0) + READ ** 2))
    for i, (y, x) in enumerate(stuck):
        darks[:, y, x] = flat[:, y, x] = 1000 + i
    return dg.CaptureData([darks.astype(np.float32)], [np.clip(flat, 0, WHITE).astype(np.float32)], [],
                          np.full((2, 2), BLACK), WHITE, "RGGB")


def test_a_defect_free_set_expects_no_defect_and_two_stuck_pixels_are_significant():
    d = _capture()
    lam = dg.defect_null_count(d)
    # read noise 1.2 DN over 8 darks, shot noise ~45 DN over 8 flat frames: far below one pixel per set
    p_dark = stats.norm.cdf(0.5 / np.sqrt(READ ** 2)) - stats.norm.cdf(-0.5 / np.sqrt(READ ** 2))
    assert lam < 128 * 128 * p_dark ** 7 and lam >= dg.COUNT_NULL_MIN
    assert dg.defect_pixels(d) == 0.0
    R = 12
    zero = [0.0] * R
    assert dg.discrepancy("defect_pixels", 0.0, zero, 1 / 128 ** 2, lam).p == 1.0
    d2 = _capture(stuck=[(10, 11), (70, 40)])
    v = dg.defect_pixels(d2)
    assert v == pytest.approx(2 / 128 ** 2)
    p_new = dg.discrepancy("defect_pixels", v, zero, 1 / 128 ** 2, dg.defect_null_count(d2)).p
    p_old = dg.discrepancy("defect_pixels", v, zero, 1 / 128 ** 2).p
    assert p_old > 0.01 / 30 and p_new < 1e-12  # Holm at 1 % over 30 statistics: now significant
    # replicates that do count defects: the replicates' law, whatever the closed form says
    some = [0.0] * (R - 2) + [1 / 128 ** 2, 2 / 128 ** 2]
    assert dg.discrepancy("defect_pixels", v, some, 1 / 128 ** 2, 1e-9).p == pytest.approx(
        dg.discrepancy("defect_pixels", v, some, 1 / 128 ** 2).p)


def test_the_dead_term_matches_a_gaussian_response_spread():
    """Responses N(m, s) with (1 - DEAD_RESPONSE) m / s = 2.5: the share below DEAD_RESPONSE m is
    Phi(-2.5) = 0.62 %; the closed form (robust SD of the measured responses) and the dead-pixel count of
    the data agree within 4 Poisson SE."""
    size = 256
    m = 2000.0
    s = (1 - dg.DEAD_RESPONSE) * m / 2.5
    rng = np.random.default_rng(3)
    d = _capture(seed=4, size=size, response=m + s * rng.standard_normal((size, size)))
    lam = dg.defect_null_count(d)
    n = dg.defect_pixels(d) * size * size
    expected = size * size * stats.norm.cdf(-2.5)
    assert abs(lam - expected) < 4 * np.sqrt(expected)
    assert abs(n - lam) < 4 * np.sqrt(lam)
