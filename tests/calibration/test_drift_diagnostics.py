"""Frame means that drift over a sequence, and a dark level that rises without Poisson variance, are
told apart from flicker and dark current (``frame_mean_drift``, ``frame_mean_jitter`` by successive
differences, ``dark_variance_slope``). Frames are drawn here with numpy; expected values are closed
forms (von Neumann's ratio of independent values is 1; a Poisson charge's variance is its mean), with
tolerances from the spread of repeated draws."""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg

BLACK, WHITE, K, READ = 64.0, 4095.0, 0.5, 2.0
H = W = 64


def frames(rng, n, level_dn=0.0, offsets=None, gains=None):
    """n frames: level (DN above black) x per-frame gain, Poisson shot noise at K, Gaussian read noise,
    plus per-frame offsets (DN)."""
    out = []
    for i in range(n):
        g = 1.0 if gains is None else gains[i]
        e = rng.poisson(level_dn * g / K, (H, W)) * K if level_dn > 0 else 0.0
        o = 0.0 if offsets is None else offsets[i]
        out.append(BLACK + e + o + rng.normal(0, READ, (H, W)))
    return np.round(np.array(out)).astype(np.float32)


def capture(darks, flats, series=None):
    return dg.CaptureData(darks, flats, [], np.full((2, 2), BLACK), WHITE, "RGGB", dark_series=series)


def test_frame_mean_drift_is_zero_for_independent_frames_and_large_for_a_drift():
    vals = []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        vals.append(dg.frame_mean_drift(capture([frames(rng, 8)], [frames(rng, 8, 1000.0)])))
    vals = np.array(vals)
    # log of a ratio whose expectation is 1: near 0 (its mean within 4 standard errors of 0 up to the
    # log's negative Jensen bias, which is below 0.15 for 8 frames)
    assert abs(vals.mean()) < 4 * vals.std(ddof=1) / np.sqrt(vals.size) + 0.15
    rng = np.random.default_rng(99)
    ramp = np.linspace(0.0, 3.0, 8)  # 3 DN over the sequence; the frame means' own sd: 0.03 DN (darks), 0.35 (flats)
    drift = dg.frame_mean_drift(capture([frames(rng, 8, offsets=ramp)], [frames(rng, 8, 1000.0, offsets=ramp)]))
    assert drift > vals.mean() + 6 * vals.std(ddof=1)


def test_frame_mean_jitter_sees_flicker_not_a_slow_drift():
    sigma = 0.01
    flick, drift, plain, steep = [], [], [], []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        d = [frames(rng, 8)]
        plain.append(dg.frame_mean_jitter(capture(d, [frames(rng, 12, 1000.0)])))
        flick.append(dg.frame_mean_jitter(capture(d, [frames(rng, 12, 1000.0, gains=1 + sigma * rng.normal(size=12))])))
        drift.append(dg.frame_mean_jitter(capture(d, [frames(rng, 12, 1000.0, gains=np.linspace(1, 1.01, 12))])))
        steep.append(dg.frame_mean_jitter(capture(d, [frames(rng, 12, 1000.0, gains=np.linspace(1, 1.05, 12))])))
    plain, flick, drift, steep = map(np.array, (plain, flick, drift, steep))
    # flicker: sigma^2 above the shot and read part (closed form of an independent per-frame gain)
    excess = flick.mean() - plain.mean()
    se = np.hypot(flick.std(ddof=1), plain.std(ddof=1)) / np.sqrt(flick.size)
    assert abs(excess - sigma ** 2) < 4 * se + 0.1 * sigma ** 2
    # a linear gain ramp adds the same step to every successive difference, taken about their mean: a 1 %
    # and a 5 % ramp over 12 frames (steps of 0.09 and 0.45 %; about 0 the 5 % one added (0.05 / 11)^2 / 2
    # = 1e-5, a 0.3 % flicker) leave the statistic where it is without them (the same frames' noise)
    for ramp in (drift, steep):
        assert abs(ramp.mean() - plain.mean()) < 4 * np.hypot(ramp.std(ddof=1), plain.std(ddof=1)) / np.sqrt(ramp.size)


def test_dark_variance_slope_is_K_squared_times_the_rate_and_zero_for_a_drifting_black():
    rate = 200.0  # e-/s
    times = (0.02, 0.5, 1.0)
    vals, drifting = [], []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        series = [(t, frames(rng, 8, level_dn=K * rate * t)) for t in times]
        vals.append(dg.dark_variance_slope(capture([series[0][1]], [], series)))
        # a black level 40 DN higher per second, no charge
        series = [(t, frames(rng, 8, offsets=np.full(8, 40.0 * t))) for t in times]
        drifting.append(dg.dark_variance_slope(capture([series[0][1]], [], series)))
    vals, drifting = np.array(vals), np.array(drifting)
    assert abs(vals.mean() - K * K * rate) < 4 * vals.std(ddof=1) / np.sqrt(vals.size) + 0.02 * K * K * rate
    assert abs(drifting.mean()) < 4 * drifting.std(ddof=1) / np.sqrt(drifting.size) + 0.02 * K * K * rate


def test_drift_statistics_not_applicable_on_short_sequences():
    rng = np.random.default_rng(0)
    value, why = dg.statistic("frame_mean_drift", capture([frames(rng, 3)], [frames(rng, 3, 500.0)]))
    assert value is None and ">= 4 frames" in why
    value, why = dg.statistic("dark_variance_slope", capture([frames(rng, 3)], []))
    assert value is None and "exposure times" in why
    with pytest.raises(dg.NotApplicable):
        dg.frame_mean_jitter(capture([], [frames(rng, 1, 500.0)]))


def _frame_fit(darks, flats=()):
    from simcam.calibration.effects import CARDS, FitContext
    from simcam.calibration.model import LoopModel

    d = capture(darks, list(flats))
    m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K, READ, READ ** 2 + 1 / 12)
    return CARDS["empirical_offset"].fit(d, m, FitContext(form="frame")), m


def test_frame_offset_fit_recovers_the_frame_levels_spread_beside_row_noise():
    """Per-frame dark offsets N(0, 1.5^2) DN beside white row offsets of 2 DN (which put 4 / H DN^2 into
    each frame's mean): the frame form's variance is 2.25 within 3 standard errors of a sample variance of
    10 x 15 degrees of freedom (2.25 sqrt(2 / 150)); without frame offsets it is ~0."""
    from simcam.calibration.effects.empirical_offset import quantile_table_moments

    rng = np.random.default_rng(11)

    def seq(frame_sd):
        f = frames(rng, 16, offsets=rng.normal(0, frame_sd, 16) if frame_sd else None)
        return f + np.round(rng.normal(0, 2.0, (16, H, 1))).astype(np.float32)

    p, _m = _frame_fit([seq(1.5) for _ in range(10)])
    var = quantile_table_moments(p.quantiles_dn)[1]
    assert p.axis == "frame" and abs(var - 2.25) < 3 * 2.25 * np.sqrt(2 / 150), var
    p0, _m = _frame_fit([seq(0.0) for _ in range(10)])
    assert quantile_table_moments(p0.quantiles_dn)[1] < 0.02


def test_frame_offset_fit_takes_a_ramp_as_its_spread_and_a_gain_drift_as_nothing():
    from simcam.calibration.effects import CARDS
    from simcam.calibration.effects.empirical_offset import quantile_table_moments

    rng = np.random.default_rng(12)
    ramp = np.linspace(0.0, 4.0, 16)  # a black level warming up by 4 DN over the sequence
    p, m = _frame_fit([frames(rng, 16, offsets=ramp) for _ in range(4)])
    assert quantile_table_moments(p.quantiles_dn)[1] == pytest.approx(np.var(ramp), rel=0.15)
    entry = CARDS["empirical_offset"].to_profile(p, m).effect
    assert entry["axis"] == "frame" and entry["temporal"] is True
    back = CARDS["empirical_offset"].from_profile(entry, m.full_scale_dn)
    assert back.axis == "frame" and np.allclose(back.quantiles_dn, p.quantiles_dn)
    # a gain that drifts shows in the flats only: the darks' frame form is null
    gains = np.linspace(0.98, 1.02, 16)
    p0, _m = _frame_fit([frames(rng, 16) for _ in range(4)], [frames(rng, 16, 1000.0, gains=gains)])
    assert CARDS["empirical_offset"].is_null(p0) or quantile_table_moments(p0.quantiles_dn)[1] < 0.02


def test_frame_form_keeps_a_dark_level_rising_with_exposure_without_shot_noise():
    """A black level that warms up over each sequence (ramp of 3 DN) and sits 1.5 DN/s higher per second of
    exposure (no Poisson charge: dark_current's fit is null on it): the frame form keeps the rise. Its
    standard error: two levels 1.98 s apart, each the mean of 16 frame means of spread ~0.9 DN
    (sqrt(2 x 0.9^2 / 16) / 1.98 = 0.16 DN/s); within 3 of them. Equal levels: no rate."""
    from simcam.calibration.effects import CARDS, FitContext
    from simcam.calibration.model import LoopModel

    rng = np.random.default_rng(13)
    ramp = np.linspace(0.0, 3.0, 16)

    def series(per_s):
        return [(t, frames(rng, 16, offsets=ramp + per_s * t)) for t in (0.02, 2.0)]

    m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K, READ, READ ** 2 + 1 / 12)
    for per_s, lo, hi in ((1.5, 1.5 - 0.48, 1.5 + 0.48), (0.0, 0.0, 0.0)):
        s = series(per_s)
        d = dg.CaptureData([s[0][1]], [], [], np.full((2, 2), BLACK), WHITE, "RGGB", dark_series=s)
        p = CARDS["empirical_offset"].fit(d, m, FitContext(form="frame"))
        assert lo <= p.rate_dn_per_s <= hi, (per_s, p.rate_dn_per_s)
        assert CARDS["dark_current"].fit(d, m, FitContext()).rate_e_per_s == 0.0 or per_s == 0.0


def test_a_frame_offset_leaves_the_read_noise_alone():
    """The read noise is measured with each frame's mean removed (photon-transfer points): a whole frame's
    offset is not in it, so adding the frame form must not lower the read noise; a column offset is in it."""
    from simcam.calibration.effects.empirical_offset import EmpiricalOffset
    from simcam.calibration.model import LoopModel

    q = list(np.linspace(-2.0, 2.0, 33))
    reads = []
    for eff in ({}, {"empirical_offset": EmpiricalOffset(quantiles_dn=q, axis="frame")},
                {"empirical_offset": EmpiricalOffset(quantiles_dn=q, axis="column")}):
        m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K, READ, READ ** 2 + 1 / 12, effects=dict(eff))
        m.refit_read()
        reads.append(m.read_dn)
    assert reads[1] == reads[0] and reads[2] < reads[0]


def test_dark_frame_jitter_is_zero_for_independent_frames_and_large_for_moving_black():
    """Without frame offsets each value is a chi-square(n)/n - 1 (n = 16 frames): sd sqrt(2/16) = 0.35, so
    the mean of 20 draws is 0 within 3 x 0.08; a 1-DN frame offset against a frame-mean noise of
    2^2 / 4096 DN^2 is ~1000."""
    rng = np.random.default_rng(14)
    vals = [dg.dark_frame_jitter(capture([frames(rng, 16)], [])) for _ in range(20)]
    assert abs(np.mean(vals)) < 3 * np.sqrt(2 / 16) / np.sqrt(20)
    moving = dg.dark_frame_jitter(capture([frames(rng, 16, offsets=rng.normal(0, 1.0, 16))], []))
    assert moving > 100
    assert dg.statistic("dark_frame_jitter", capture([], [frames(rng, 4, 500.0)]))[0] is None


def test_the_frame_form_stays_the_frame_form_when_dark_current_joins():
    """``dark_current`` joining refits the frame form (its rate is the rise dark current leaves); the refit
    runs with the joining effect's fit context, and must keep the model's form (it became the column form)."""
    from simcam.calibration.effects import FitContext
    from simcam.calibration.effects.empirical_offset import EmpiricalOffset
    from simcam.calibration.fit import fit_effect
    from simcam.calibration.model import LoopModel

    rng = np.random.default_rng(15)
    s = [(t, frames(rng, 12, offsets=rng.normal(0, 1.0, 12))) for t in (0.02, 2.0)]
    d = dg.CaptureData([s[0][1]], [], [], np.full((2, 2), BLACK), WHITE, "RGGB", dark_series=s)
    m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K, READ, READ ** 2 + 1 / 12,
                  effects={"empirical_offset": EmpiricalOffset(quantiles_dn=list(np.linspace(-1, 1, 33)), axis="frame")})
    m2 = fit_effect("dark_current", d, m, FitContext(diagnostic="dark_signal_slope"))
    assert m2.effects["empirical_offset"].axis == "frame"
