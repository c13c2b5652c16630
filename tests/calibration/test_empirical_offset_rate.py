"""The frame form of ``empirical_offset`` keeps the dark level's rise per second of exposure when it is
beyond 3 standard errors; a level that drifts within each sequence (a ramp over its frames) is not noise
of the sequence's level (``empirical_offset.level_variance``). Made with numpy: darks at 0.02 s and 2 s,
8 frames of 32 x 48 pixels, 1-DN white noise, a ramp of 3.6 DN over each sequence and a rise of
0.62 DN/s (the independent simulator's black drift at ``--seed 2030``, whose rise the spread of the ramped
frame means had hidden: SE 0.3 DN/s, the rise 2.1 of them)."""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects.empirical_offset import RATE_Z, _exposure_rate, level_variance
from simcam.calibration.model import LoopModel

BLACK, N, RAMP, RISE = 256.0, 8, 3.6, 0.62
TIMES = (0.02, 2.0)


def _series(rise: float, ramp: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    out = []
    for t in TIMES:
        level = BLACK + rise * t + ramp * (np.arange(N) / (N - 1) - 0.5)
        out.append((t, (level[:, None, None] + rng.normal(0.0, 1.0, (N, 32, 48))).astype(np.float32)))
    return out


def _data(series):
    return dg.CaptureData([series[0][1]], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB", dark_series=series)


def _model():
    return LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, 0.0, 1.0, 1.0)


def test_a_rise_beside_a_ramp_is_kept():
    series = _series(RISE, RAMP)
    # the frame means' spread about their mean (the ramp's) would give SE ~0.3 DN/s: the rise hidden
    plain = [np.var(f.mean(axis=(1, 2)), ddof=1) / N for _t, f in series]
    assert RISE < RATE_Z * np.sqrt(sum(plain)) / (TIMES[1] - TIMES[0])
    se = np.sqrt(sum(level_variance(f.mean(axis=(1, 2)).astype(np.float64)) for _t, f in series)) / (TIMES[1] - TIMES[0])
    rate = _exposure_rate(_data(series), _model())
    assert rate != 0.0 and abs(rate - RISE) < 3 * se, (rate, se)


def test_no_rise_beside_a_ramp_is_not_kept():
    assert _exposure_rate(_data(_series(0.0, RAMP)), _model()) == 0.0


@pytest.mark.parametrize("ramp", [0.0, RAMP])
def test_the_level_variance_is_that_of_the_frames_noise(ramp):
    """Over 400 sequences, the mean of ``level_variance`` is the frame mean's noise variance over N, with
    or without a ramp (a straight line is taken off; the residuals keep n - 2 degrees of freedom)."""
    rng = np.random.default_rng(1)
    sd = 0.05
    v = [level_variance(ramp * (np.arange(N) / (N - 1) - 0.5) + rng.normal(0.0, sd, N)) for _ in range(400)]
    # the estimator's SE over 400 draws: var * sqrt(2 / (N - 2)) / N / sqrt(400)
    assert abs(np.mean(v) - sd * sd / N) < 4 * sd * sd / N * np.sqrt(2 / (N - 2)) / 20
