"""``empirical_response``: a response that curves by a different amount in every pixel (outside the loop's
vocabulary). References: the half-normal law's closed-form quantiles (scipy.stats), the closed-form growth
of the flats' relative fixed-pattern variance, ``sd(c)^2 (L_hi^2 - L_lo^2) / s^2``, with the standard error of
the covariance estimate; the generator is ``loop_generator``'s ``pixel_curvature`` (``c_p ~ N(c_mean, c_sd^2)``).
"""

from __future__ import annotations

import numpy as np
import pytest
from loop_generator import SensorSpec, capture_set
from loop_matrix import in_memory_capture
from scipy import stats

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, Fit, FitContext
from simcam.calibration.effects.empirical_response import _law_moments, curvature_deviations, measured_law


def _group(effects, side=128, seed=3):
    from simcam.calibration.loop import Group, LoopConfig

    cs = in_memory_capture(capture_set(SensorSpec(height=side, width=side, effects=effects), seed=seed))
    return Group(cs.group(800), LoopConfig(), [])


def _fit(effects, **kw):
    from simcam.calibration.fit import base_fit

    g = _group(effects, **kw)
    base = base_fit(g.fit_data)
    out = CARDS["empirical_response"].fit(g.fit_data, base, FitContext(diagnostic="flat_spread_growth"))
    return g, base, (out.params if isinstance(out, Fit) else out)


def test_measured_law_keeps_a_skewed_shape_at_the_given_spread():
    """Half-normal deviations (every pixel compressing, some more) keep their skew: the kept quantiles are the
    half-normal's, centred and scaled to the given sd, within 5 % of the sd (the piecewise-linear law between 33
    quantiles is not the half-normal: its sd is matched exactly, its quantiles approximately)."""
    x = np.abs(np.random.default_rng(0).standard_normal(200_000))
    q = np.array(measured_law(x, 0.03))
    mean, sd = _law_moments(q)
    assert mean == pytest.approx(0.0, abs=1e-12) and sd == pytest.approx(0.03, rel=1e-9)
    p = np.linspace(0.0, 1.0, q.size)[1:-1]
    ref = (stats.halfnorm.ppf(p) - stats.halfnorm.mean()) / stats.halfnorm.std() * 0.03
    assert np.max(np.abs(q[1:-1] - ref)) < 0.05 * 0.03
    assert stats.skew(np.interp(np.linspace(0, 1, 10_001), np.linspace(0, 1, q.size), q)) > 0.5


def test_fit_recovers_the_curvature_spread_and_refuses_a_gain():
    """On flats whose pixels bend by their own amount (c_p ~ N(-4 %, 5 %^2) at white, 128 x 128, 6 fit frames)
    the spread is the generator's within 4 standard errors of the covariance estimate, the mean curvature is the
    photon-transfer curve's, and the per-pixel deviations follow c_p; a gain alone (PRNU 2 %) has the same
    relative spread at both levels and the fit is null, saying why."""
    g, base, p = _fit({"pixel_curvature": {"c_mean": -0.04, "c_sd": 0.05}})
    s = base.full_scale_dn
    lo, hi = dg.flat_level_pair(dg.prnu_by_level(g.fit_data))
    k_se = float(np.hypot(lo[2], hi[2])) / (hi[0] ** 2 - lo[0] ** 2)
    sd_se = k_se * s * s / (2 * 0.05)  # delta method: c_sd = sqrt(k) s
    assert p.c_sd == pytest.approx(0.05, abs=4 * sd_se)
    assert p.c_mean == pytest.approx(-0.04, abs=0.02)
    assert p.growth_z > 4 and len(p.quantiles) == 33
    dev = curvature_deviations(g.fit_data, s)
    from loop_generator import HiddenEffectSensor

    c = HiddenEffectSensor(SensorSpec(height=128, width=128,
                                      effects={"pixel_curvature": {"c_mean": -0.04, "c_sd": 0.05}})).curvature
    planes = np.concatenate([c[dy::2, dx::2].ravel() for dy, dx in dg.PLANE_OFFSETS])
    # measured pixel by pixel: the signal, sd(c) (L_hi - L_lo) / s = 3 %, is below the dimmer flat's relative
    # temporal noise over 6 frames (~5 % at 15 % of full scale), so the correlation is ~0.5 at best
    assert np.corrcoef(dev, planes)[0, 1] > 0.3

    _g, _b, q = _fit({"prnu": {"sigma": 0.02}})
    card = CARDS["empirical_response"]
    assert card.is_null(q) and "does not grow with the signal" in card.null_reason(q)


def test_loop_adds_the_empirical_response_not_nonlinearity_or_prnu():
    """The loop names no effect of the vocabulary for a per-pixel curvature: the common bend alone
    (``nonlinearity``) leaves the flats' growing fixed pattern, a gain (``prnu``) is refused by its level
    check, and the empirical component explains both; the held-out structured KL drops by >= 80 %."""
    from simcam.calibration.loop import LoopConfig, run_loop

    effects = {"pixel_curvature": {"c_mean": -0.04, "c_sd": 0.06}}
    r = run_loop(in_memory_capture(capture_set(SensorSpec(effects=effects))), LoopConfig())[0]
    assert set(r.model.effects) == {"empirical_response"}
    it = next(i for i in r.iterations if i["accepted"] and i["effect"] == "empirical_response")
    assert it["not_in_vocabulary"].startswith("pixel, fixed, multiplicative")
    b, f = r.heldout_base["kl_structured"], r.heldout_final["kl_structured"]
    assert b > 0 and f <= 0.2 * b, (b, f)
