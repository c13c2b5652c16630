"""The ``dark_current`` card and the choice of the darks the loop's dark diagnostics use (the shortest
exposure time, EMVA 1288 Release 4.0): darks at other exposure times form the dark-current series."""

import numpy as np
import pytest

from loop_generator import HiddenEffectSensor, SensorSpec
from loop_matrix import in_memory_capture, run_case
from simcam.calibration import diagnostics as dg
from simcam.calibration.capture import Sequence
from simcam.calibration.effects import CARDS, FitContext
from simcam.calibration.loop import Group, LoopConfig, dark_exposure
from simcam.calibration.model import LoopModel

RATE, LOG_SIGMA, K, READ = 40.0, 0.3, 2.0, 3.0
TIMES, FRAMES = (0.01, 0.5, 1.0), 8


def _series(times=TIMES, seed=3):
    spec = SensorSpec(K=K, read_dn=READ, bits=12, effects={"dark_current": {"rate_e_per_s": RATE,
                                                                          "log_sigma": LOG_SIGMA}})
    sensor = HiddenEffectSensor(spec)
    rng = np.random.default_rng(seed)
    series = [(t, sensor.frames(0.0, FRAMES, rng, t)) for t in times]
    return spec, sensor, series


def _fit(series, gain=K):
    d = dg.CaptureData([series[0][1]], [], [], np.full((2, 2), 64.0), 4095.0, "RGGB", dark_series=series)
    m = LoopModel("RGGB", np.full((2, 2), 64.0), 4095.0, gain, READ, READ ** 2 + 1 / 12)
    return d, CARDS["dark_current"].fit(d, m, FitContext())


def test_fit_recovers_the_rate_within_its_standard_error():
    spec, sensor, series = _series()
    d, p = _fit(series)
    true_rate = float(sensor.dark_rate.mean())  # this sensor's pixels (the DCNU draw moves the mean a little)
    # standard error of the mean-slope estimate: each exposure's mean over H x W x frames values of
    # variance read^2 + K^2 rate t (+ 1/12 quantisation), through the least-squares slope weights
    t = np.asarray(TIMES)
    c = (t - t.mean()) / np.sum((t - t.mean()) ** 2)
    n = spec.height * spec.width * FRAMES
    var_mean = (READ ** 2 + 1 / 12 + K ** 2 * true_rate * t) / n
    se = float(np.sqrt(np.sum(c ** 2 * var_mean))) / K
    assert abs(p.rate_e_per_s - true_rate) < 3 * se, (p.rate_e_per_s, true_rate, se)
    assert p.gain_dn_per_e == K and p.read_exposure_s == 0.01
    assert p.log_sigma == pytest.approx(LOG_SIGMA, abs=0.1)
    # without a system gain the darks give it (variance slope / mean slope: the dark electrons are Poisson)
    _, p0 = _fit(series, gain=0.0)
    assert p0.gain_dn_per_e == pytest.approx(K, rel=0.1) and p0.rate_e_per_s == pytest.approx(true_rate, rel=0.1)


def test_not_applicable_with_one_exposure_time():
    _spec, _sensor, series = _series(times=(0.5,))
    d, p = _fit(series)
    assert dg.statistic("dark_signal_slope", d) == (None, "needs darks at >= 2 exposure times")
    assert CARDS["dark_current"].is_null(p)
    # two sequences at the same exposure time are no series either
    _spec, _sensor, series = _series(times=(0.5, 0.5))
    assert dg.statistic("dark_signal_slope", _fit(series)[0]) == (None, "needs darks at >= 2 exposure times")


def _seq(name, t, n, kind="dark"):
    return Sequence(name, kind, np.zeros((n, 8, 8), np.float32) + 64, 100, t, "RGGB", np.full((2, 2), 64.0), 1023.0)


def test_dark_diagnostics_use_the_shortest_exposure():
    # the long darks hold more frames: still the shortest exposure time (EMVA 1288 R4.0)
    seqs = [_seq("long", 2.0, 20), _seq("short", 0.02, 8)]
    assert dark_exposure(seqs) == 0.02
    assert dark_exposure([_seq("a", None, 4), _seq("b", 0.5, 4)]) == 0.5
    assert dark_exposure([_seq("a", None, 4)]) == -1.0 and dark_exposure([]) is None
    notes = []
    g = Group(seqs + [_seq("flat", 0.01, 8, "flat")], LoopConfig(), notes)
    assert [f.shape[0] for f in g.fit_data.darks] == [4]  # the 0.02 s darks' fit half only
    assert sorted(t for t, _ in g.fit_data.dark_series) == [0.02, 2.0]
    assert any("darks at 0.02 s used for the dark diagnostics" in n and "2 s only in the dark-current" in n
               for n in notes)
    specs = g.specs(LoopModel("RGGB", np.full((2, 2), 64.0), 1023.0, 2.0, 3.0, 9.0), g.fit)
    assert [(sp.kind, sp.exposure_s, sp.series_only) for sp in specs] == [
        ("dark", 2.0, True), ("dark", 0.02, False), ("flat", 0.01, False)]
    # one exposure time: no series
    g1 = Group([_seq("short", 0.02, 8)], LoopConfig(), [])
    assert g1.fit_data.dark_series is None


def test_loop_names_dark_current_alone():
    r = run_case(("dark_current",))
    assert list(r.model.effects) == ["dark_current"] and not r.unexplained
    p = r.model.effects["dark_current"]
    assert p.rate_e_per_s == pytest.approx(RATE, rel=0.1)
    it = r.iterations[0]
    assert it["accepted"] and it["heldout"]["kl_structured_after"] < 0.2 * it["heldout"]["kl_structured_before"]


def test_single_dark_exposure_reports_dark_current_not_applicable():
    from loop_generator import capture_set

    from simcam.calibration.loop import run_loop

    caps = capture_set(SensorSpec(), seed=7)
    r = run_loop(in_memory_capture(caps), LoopConfig(replicates=8, heldout_replicates=4))[0]
    assert r.not_applicable["dark_signal_slope"] == "needs darks at >= 2 exposure times"


def test_the_halves_interleave_so_a_drifting_level_spreads_both_alike():
    """Even frames fit, odd frames are held out: a level that drifts over the sequence (a black level
    warming up) has the same mean and spread of frame levels in both halves, as a stationary model
    needs; a split in time would put the held-out half ~half the drift above the fit half."""
    seq = _seq("ramp", 0.02, 9)
    seq.frames[:] += np.arange(9, dtype=np.float32)[:, None, None]  # frame i reads 64 + i
    g = Group([seq], LoopConfig(), [])
    (_, fit, _), (_, held, _) = g.fit[0], g.held[0]
    assert fit[:, 0, 0].tolist() == [64, 66, 68, 70, 72] and held[:, 0, 0].tolist() == [65, 67, 69, 71]
    assert abs(fit.mean() - held.mean()) <= 1.0  # a time split: 66 against 70.5
