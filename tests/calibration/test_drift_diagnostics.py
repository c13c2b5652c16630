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
