"""Held-out KL of the loop (simcam.calibration.heldout): the Jeffreys-smoothed estimator, its sampling
floor against two-sample simulations, and the structured (aggregated-noise) marginals on noise made
here with numpy (independent of simcam's noise code)."""

import numpy as np
import pytest
from scipy import stats

from simcam.calibration.heldout import KL_EDGES, kl_sampling_floor, marginal_kl
from simcam.calibration.heldout import kl_counts, kl_floor, structured_kl

# sizes of the loop's held-out pixel KL on the test captures: 5 sequences x 6 held-out frames x 64 x 64
# values, 8 simulated replicates of them
N = 5 * 6 * 64 * 64
M = 8 * N


def test_estimator_closed_form_and_model_empty_bins():
    # data counts (3, 1) on two bins, model counts (4, 0): q = (4.5, 0.5) / 5 (half a count per bin)
    kl = 0.75 * np.log(0.75 / 0.9) + 0.25 * np.log(0.25 / 0.1)
    assert kl_counts([3, 1], [4, 0]) == pytest.approx(kl, rel=1e-12)
    # a data-only tail (hot pixels: 0.2 % of values at +0.5) counts: ~ p log(p / (0.5 / (M + 33)))
    rng = np.random.default_rng(0)
    real = rng.normal(0, 0.003, N)
    real[: N // 500] = 0.5
    model = rng.normal(0, 0.003, M)
    p = (N // 500) / N
    assert marginal_kl(real, model) > 0.8 * p * np.log(p / (0.5 / (M + 33)))


@pytest.mark.parametrize("sigma", [0.003, 0.02])  # dark-like (~10 occupied bins) and flat-like (~50)
def test_floor_is_the_mean_kl_of_two_samples_of_one_law(sigma):
    """Two independent samples (N, M) of one Gaussian: the mean KL over R = 30 pairs equals the floor
    (exact binomial expectation on the true binned law) within 4 SE of that mean (SE = sample SD /
    sqrt(R)); the floor from the pooled histogram (what the loop uses, kl_sampling_floor) is the same
    within 3 %, its sampling error (~1 / sqrt(occupied bins) of the tail terms) included."""
    rng = np.random.default_rng(1)
    pi = np.diff(stats.norm.cdf(KL_EDGES, scale=sigma))
    floor = kl_floor(pi, N, M)
    kls, pooled = [], []
    for _ in range(30):
        a, b = rng.normal(0, sigma, N), rng.normal(0, sigma, M)
        kls.append(marginal_kl(a, b))
        pooled.append(kl_sampling_floor(a, b))
    kls = np.asarray(kls)
    assert abs(kls.mean() - floor) < 4 * kls.std(ddof=1) / np.sqrt(kls.size)
    assert np.mean(pooled) == pytest.approx(floor, rel=0.03)
    # Miller-Madow's second order (B - 1)(1/2N + 1/2M), B the expected number of occupied bins, is its
    # large-count limit: close (15 %) where most bins are well filled; sparse tail bins add more
    if sigma == 0.02:
        b = np.sum(1 - (1 - pi) ** N)
        assert floor == pytest.approx((b - 1) * (1 / (2 * N) + 1 / (2 * M)), rel=0.15)


def _residuals(rng, row_sigma=0.0, n=6, h=64, w=64, seqs=3):
    """Per sequence (n, h, w) Gaussian noise (unit variance) plus row offsets N(0, row_sigma^2) per frame and row."""
    return [rng.normal(0, 1, (n, h, w)) + rng.normal(0, row_sigma, (n, h, 1)) for _ in range(seqs)]


def test_structured_kl_of_a_right_model_is_zero_and_sees_row_noise():
    rng = np.random.default_rng(2)
    fixed = [False] * 3
    real = _residuals(rng, 0.0)
    sims = [_residuals(rng, 0.0) for _ in range(8)]
    ok = structured_kl(real, fixed, sims)
    # the same law: no family's KL exceeds its floor by 4 SD (each family: P ~ 1e-4 under chi-square)
    assert ok["kl"] == 0.0 and set(ok["families"]) == {"pixel", "row", "column", "temporal", "block", "frame"}
    for fam in ok["families"].values():
        assert abs(fam["z"]) < 4
        # i.i.d. values here: the replicate (leave-one-out) floor and the binomial one agree within
        # the replicates' SE (sd / sqrt(8)) x 4
        assert abs(fam["floor"] - fam["floor_iid"]) < 4 * fam["sd"] / np.sqrt(8) + 1e-12
    # row noise of 0.5 x the pixel sigma: row means of 64 pixels have variance 1/64 + 0.25, 17 x the model's
    # (KL of two zero-mean Gaussians 0.5 (r - 1 - ln r) = 6.6, capped by the data binning) -> the row
    # family alone is large, the one-pixel family barely moves (variance ratio 1.25: KL 0.013)
    real_rows = _residuals(rng, 0.5)
    res = structured_kl(real_rows, fixed, sims)
    assert res["families"]["row"]["significant"] and res["families"]["row"]["excess"] > 1.0
    assert res["families"]["pixel"]["excess"] < 0.05
    # a model with the row noise, 20 % too small in sigma: the excess shrinks by > 80 %
    sims_rows = [_residuals(rng, 0.4) for _ in range(8)]
    part = structured_kl(real_rows, fixed, sims_rows)
    assert part["kl"] < 0.2 * res["kl"] and part["families"]["row"]["excess"] > 0
