"""``code_occupancy`` tested as a count: the codes of the span that no value uses.

Darks of a 5-DN ADC under 0.9 DN of read noise sit on two codes, 5 DN apart: 2 of the 6 codes of their
span are used (occupancy 1/3), while a 1-DN model's replicates use every code of theirs (occupancy 1 in
each). With the t law the replicates' spread is only the statistic's one-code floor (1/6 of the span), so
z = -3.9 and p = 0.0027: not significant among ~30 statistics (Holm's first level 0.01 / 30), and a real
5-DN quantiser went unnamed at ISO 100 while ``dsnu`` was added to explain what its coarse codes did to the
dark map. Four empty codes where the model leaves none is a count: the gamma-Poisson predictive law of the
replicates' counts (``count_law``) gives p ~ 1e-5.
"""

import numpy as np
import pytest
from scipy import stats

from simcam.calibration import diagnostics as dg

BLACK, WHITE = 256.0, 4095.0


def _darks(step: float, read: float, seed: int, n=8, size=64) -> dg.CaptureData:
    rng = np.random.default_rng(seed)
    x = BLACK + 0.9 + read * rng.standard_normal((n, size, size))
    codes = np.round(x / step) * step
    return dg.CaptureData([codes.astype(np.float32)], [], [], np.full((2, 2), BLACK), WHITE, "RGGB")


def test_darks_on_two_coarse_codes_are_significant_against_a_fine_adc():
    d = _darks(5.0, 0.9, seed=1)
    value = dg.code_occupancy(d)
    floor = dg.resolution("code_occupancy", d)
    assert value == pytest.approx(2 / 6) and floor == pytest.approx(1 / 6)  # codes 255 and 260 of 255..260
    sims = [dg.code_occupancy(_darks(1.0, 0.9, seed=100 + r)) for r in range(12)]
    assert sims == [1.0] * 12
    disc = dg.discrepancy("code_occupancy", value, sims, floor)
    # the predictive law of a new count after 12 replicates that counted 0: negative binomial (1/2, 12/13)
    expected = 2 * stats.nbinom(0.5, 12 / 13).sf(3)
    assert disc.p == pytest.approx(expected) and disc.p < 0.01 / 30
    # the t law on the one-code floor alone (the former test): not significant among 30 statistics
    z = (value - 1.0) / (floor * np.sqrt(1 + 1 / 12))
    assert 2 * stats.t.sf(abs(z), 11) > 0.01 / 30


def test_a_coarse_model_reproducing_the_codes_is_not_refuted():
    d = _darks(5.0, 0.9, seed=2)
    sims = [dg.code_occupancy(_darks(5.0, 0.9, seed=200 + r)) for r in range(12)]
    disc = dg.discrepancy("code_occupancy", dg.code_occupancy(d), sims, dg.resolution("code_occupancy", d))
    assert disc.p > 0.1


def test_a_fine_adc_against_its_own_model_counts_no_empty_code():
    d = _darks(1.0, 0.9, seed=3)
    sims = [dg.code_occupancy(_darks(1.0, 0.9, seed=300 + r)) for r in range(12)]
    assert dg.discrepancy("code_occupancy", dg.code_occupancy(d), sims, dg.resolution("code_occupancy", d)).p == 1.0
