"""Dark current is Poisson charge: the dark level and the dark temporal variance rise together,
``K mu_I t`` and ``K^2 mu_I t`` (EMVA 1288 Release 4.0, the mean and variance methods of the dark
current). ``series_fit`` compares the two against their standard errors; a level that rises without
the variance (a black level drifting with the exposure time) is not taken for dark current.

The darks are made here with numpy (Poisson electrons, Gaussian read noise, rounding), not with
simcam's noise code or the loop's generators.
"""

import numpy as np
import pytest

from simcam.calibration.dark_current import POISSON_Z, series_fit

H, W, N = 96, 128, 8
K, READ, BLACK = 2.0, 3.0, 64.0
TIMES = (0.02, 2.0)


def _darks(rate_e_per_s: float, level_dn_per_s: float, seed: int, log_sigma: float = 0.0) -> list:
    """Dark sequences at TIMES: Poisson(rate_i t) electrons x K, read noise, a level rising by
    ``level_dn_per_s`` t without shot noise, rounded to integer codes."""
    rng = np.random.default_rng(seed)
    rate = rate_e_per_s * rng.lognormal(-0.5 * log_sigma ** 2, log_sigma, (H, W)) if log_sigma else rate_e_per_s
    out = []
    for t in TIMES:
        e = rng.poisson(np.broadcast_to(rate * t, (N, H, W)))
        f = BLACK + K * e + rng.normal(0.0, READ, (N, H, W)) + level_dn_per_s * t
        out.append((t, np.round(f)))
    return out


def test_poisson_dark_current_passes_and_keeps_the_mean_method():
    r = series_fit(_darks(5.0, 0.0, seed=1, log_sigma=0.3), K)
    assert abs(r["poisson_z"]) < 3
    assert r["non_poisson_dn_per_s"] == 0.0
    # the mean method: rate = mean slope / K, within 3 standard errors of the true 5 e-/s (the DCNU draw
    # of this sensor moves its mean rate by ~0.3 / sqrt(H W) relative: far inside that)
    assert abs(r["e_per_s"] - 5.0) < 3 * r["dn_per_s_se"] / K + 5.0 * 0.3 * 3 / np.sqrt(H * W)


def test_a_level_rising_without_shot_noise_is_not_dark_current():
    r = series_fit(_darks(0.0, 0.5, seed=2), K)
    assert r["poisson_z"] < -POISSON_Z
    # the variance method gives the Poisson part: none (its SE in e-/s is se_v / K^2)
    assert abs(r["e_per_s"]) < 3 * r["dn2_per_s_se"] / K ** 2 + 1e-12
    assert r["non_poisson_dn_per_s"] == pytest.approx(0.5, abs=3 * r["dn_per_s_se"])


def test_dark_current_beside_a_rising_level_keeps_only_its_poisson_part():
    r = series_fit(_darks(2.0, 6.0, seed=3), K)  # mean slope 4 + 6 DN/s, variance slope 8 DN^2/s
    assert r["poisson_z"] < -POISSON_Z
    assert r["e_per_s"] == pytest.approx(2.0, abs=3 * r["dn2_per_s_se"] / K ** 2)
    assert r["non_poisson_dn_per_s"] == pytest.approx(6.0, abs=3 * np.hypot(r["dn_per_s_se"], r["dn2_per_s_se"] / K))


def test_the_consistency_z_is_standard_normal_under_poisson_charge():
    """The standard errors are right: over 40 independent sensors with Poisson dark current the z of
    (variance slope - K x mean slope) has mean 0 (SE 1/sqrt(40)) and SD 1 (a sample SD of 40 draws
    lies in [0.75, 1.3] with probability > 0.99)."""
    z = np.array([series_fit(_darks(3.0, 0.0, seed=100 + i), K)["poisson_z"] for i in range(40)])
    assert abs(z.mean()) < 3 / np.sqrt(40), z
    assert 0.75 < z.std(ddof=1) < 1.3, z


def test_no_test_without_a_measured_gain():
    # the gain taken from the darks (variance slope / mean slope) makes the two methods agree by construction
    r = series_fit(_darks(0.0, 0.5, seed=4), None)
    assert r["poisson_z"] == 0.0 and r["non_poisson_dn_per_s"] == 0.0


def test_the_card_fits_no_dark_current_to_a_level_rising_without_shot_noise_and_says_why():
    from simcam.calibration import diagnostics as dg
    from simcam.calibration.effects import CARDS, FitContext
    from simcam.calibration.model import LoopModel

    series = _darks(0.0, 0.5, seed=6)
    d = dg.CaptureData([series[0][1]], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB", dark_series=series)
    m = LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, K, READ, READ ** 2 + 1 / 12)
    card = CARDS["dark_current"]
    p = card.fit(d, m, FitContext())
    assert card.is_null(p)
    assert p.non_poisson_dn_per_s == pytest.approx(0.5, rel=0.1)
    assert "not Poisson charge" in card.null_reason(p)
    # a Poisson dark current is fitted as before, with nothing left over
    series = _darks(5.0, 0.0, seed=7)
    d = dg.CaptureData([series[0][1]], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB", dark_series=series)
    p = card.fit(d, m, FitContext())
    assert not card.is_null(p) and p.non_poisson_dn_per_s == 0.0 and card.null_reason(p) is None
