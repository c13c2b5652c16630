"""Attribution by held-out model comparison (simcam.calibration.attribution), against closed forms and
scipy's Student t, and in the loop: every proposed effect is scored, the best one that explains the
most is chosen (no precedence table)."""

import math

import numpy as np
import pytest
from scipy import stats

from simcam.calibration import diagnostics as dg
from simcam.calibration.attribution import GAIN_Z, MIN_GAIN, Comparison, compare, predictive_logpdf, t_logpdf


def test_t_logpdf_is_the_predictive_student_t():
    sims = np.array([1.0, 2.0, 4.0, 3.5, 2.5])
    R = sims.size
    scale = sims.std(ddof=1) * math.sqrt(1 + 1 / R)
    ref = stats.t.logpdf(2.9, R - 1, loc=sims.mean(), scale=scale)
    assert t_logpdf(2.9, sims, 0.0) == pytest.approx(ref, rel=1e-12)
    # the floor replaces a smaller spread (a statistic on a discrete lattice)
    flat = np.full(6, 3.0)
    assert t_logpdf(3.0, flat, 0.5) == pytest.approx(stats.t.logpdf(0.0, 5, scale=0.5 * math.sqrt(7 / 6)))


def test_no_gain_between_identical_models():
    rng = np.random.default_rng(1)
    sims = {f"d{i}": list(rng.normal(size=8)) for i in range(5)}
    values = {k: 0.3 for k in sims}
    c = compare(values, {k: 0.0 for k in sims}, sims, sims)
    assert c.gain == 0.0 and c.sd == 0.0 and c.diagnostics == 5 and not c.beats()


def test_gain_is_the_log_density_difference_and_names_the_statistic_that_moved():
    """Current model misses one statistic by 10 of its SDs, the candidate centres it; the other statistics
    are the same draws in both (common random numbers): the gain is exactly the t log-density difference
    of the one that moved, and its jackknife SE comes from that statistic's replicates alone."""
    rng = np.random.default_rng(2)
    base = rng.normal(size=8)
    cur = {"moved": list(base), "same": list(rng.normal(size=8))}
    cand = {"moved": list(base + 10.0), "same": cur["same"]}
    values = {"moved": 10.0 + base.mean(), "same": 0.1}
    floors = {"moved": 0.0, "same": 0.0}
    c = compare(values, floors, cur, cand)
    expect = t_logpdf(values["moved"], np.asarray(cand["moved"]), 0.0) - t_logpdf(values["moved"], base, 0.0)
    assert c.gain == pytest.approx(expect, rel=1e-12)
    assert c.per_diagnostic["same"] == 0.0 and c.top(1)[0][0] == "moved"
    # leave-one-out by hand
    loo = [t_logpdf(values["moved"], np.delete(base + 10.0, r), 0.0) - t_logpdf(values["moved"], np.delete(base, r), 0.0)
           for r in range(8)]
    sd = math.sqrt(7 / 8 * sum((x - np.mean(loo)) ** 2 for x in loo))
    assert c.sd == pytest.approx(sd, rel=1e-12)
    assert c.beats()


def test_beats_needs_both_the_noise_gate_and_the_minimum_gain():
    assert Comparison(MIN_GAIN * 1.5, MIN_GAIN * 1.5 / GAIN_Z * 0.9, {}, 3).beats()
    assert not Comparison(MIN_GAIN * 1.5, MIN_GAIN * 1.5 / GAIN_Z * 1.1, {}, 3).beats()  # within the noise
    assert not Comparison(MIN_GAIN * 0.9, 0.0, {}, 3).beats()  # certain but too small


def test_statistics_undefined_on_a_replicate_are_left_out():
    cur = {"a": [1.0, 2.0, 3.0, 4.0], "b": [1.0, None, 3.0, 4.0]}
    c = compare({"a": 2.0, "b": 2.0}, {"a": 0.0, "b": 0.0}, cur, cur)
    assert c.diagnostics == 1


def test_loop_scores_every_proposed_effect_and_takes_the_one_that_explains_most():
    """Telegraph pixels beside hot pixels: the dark tails propose heavy_tail_read, the two-level count
    rtn, the persistent outliers hot_pixels. All three are fitted and scored on held-out frames;
    rtn explains the tails *and* the two-level count, so it has the largest gain and is added
    first, then hot_pixels; heavy_tail_read never is (the held-out score decides, not a table)."""
    from loop_matrix import run_case

    r = run_case(("rtn", "hot_pixels"))
    assert set(r.model.effects) == {"rtn", "hot_pixels"}
    first = r.iterations[0]
    tried = {c["effect"]: c for c in first["candidates"]}
    assert {"rtn", "hot_pixels", "heavy_tail_read"} <= set(tried)
    assert first["effect"] == "rtn" and tried["rtn"]["chosen"]
    scored = [c for c in first["candidates"] if "heldout_gain" in c]
    assert max(scored, key=lambda c: c["heldout_gain"])["effect"] == "rtn"
    assert "telegraph_pixels" in {m["diagnostic"] for m in tried["rtn"]["moved_most"]}
    assert "heavy_tail_read" not in r.model.effects


def test_no_precedence_table_left():
    assert not hasattr(dg, "PRECEDENCE")


def test_race_with_no_fitted_candidate_is_empty():
    # every proposed effect's fit was skipped (e.g. amp_glow without two dark exposures): the race has
    # nothing to score, and the iteration reports the proposing diagnostics as unexplained (it crashed with
    # "max() arg is an empty sequence" on an independent simulator's amp-glow set)
    from types import SimpleNamespace

    from simcam.calibration.loop import Loop

    fake = SimpleNamespace(cfg=SimpleNamespace(heldout_replicates=12))
    assert Loop._race(fake, [], {}) == []


def test_count_law_is_the_gamma_poisson_predictive():
    # closed form: with S = 0 over R replicates the predictive is NB(r = 1/2, p = R / (R + 1)):
    # P(N = 0) = p^r, P(N = 1) = r (1 - p) p^r
    R = 16
    law = dg.count_law("defect_pixels", np.zeros(R), 1 / 1000)
    p = R / (R + 1)
    assert law.pmf(0) == pytest.approx(p ** 0.5, rel=1e-12)
    assert law.pmf(1) == pytest.approx(0.5 * (1 - p) * p ** 0.5, rel=1e-12)
    # five defects where every replicate has none: a count far beyond the t law's floor
    d = dg.discrepancy("defect_pixels", 5 / 1000, [0.0] * R, 1 / 1000)
    assert d.p == pytest.approx(2 * law.sf(4), rel=1e-12) and d.p < 1e-6 and d.z > 5
    assert dg.discrepancy("defect_pixels", 0.0, [0.0] * R, 1 / 1000).p == 1.0
    # many pixels, or over-dispersed replicates: the t law (count_law gives None)
    assert dg.count_law("defect_pixels", np.full(R, 10 / 1000), 1 / 1000) is None
    assert dg.count_law("defect_pixels", np.array([0, 0, 0, 5] * 4) / 1000, 1 / 1000) is None
    assert dg.count_law("lag1_corr", np.zeros(R), 1 / 1000) is None
    # the held-out score uses the same law: log pmf over the one-pixel unit
    assert predictive_logpdf("defect_pixels", 2 / 1000, np.zeros(R), 1 / 1000) == pytest.approx(
        law.logpmf(2) + np.log(1000), rel=1e-12)
