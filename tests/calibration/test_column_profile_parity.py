"""The fixed column profile (``col_fpn_excess``, ``column_fpn``'s fit, ``empirical_lines``) is not moved by
the planes' median centring on quantised darks. The darks come from the independent simulator
(``tests/indepsim``): an ADC whose code 256 spans [255.40, 257.01) (its DNL at a 64-code carry) under a
black of 256 DN. There, a 4-frame mean map sits on quarter codes and a plane's median jumps by a step
from one choice of frames to another; the jump alternates over the columns and counted as a fixed
column pattern: the statistic spread over +-2 of the white level between frame subsets, where a white
column profile gives 1/sqrt(W) (the closed form of the covariance of two independent white profiles
over their variance)."""

import numpy as np

from simcam.calibration import diagnostics as dg
from tests.indepsim.cases import CASES, case_spec
from tests.indepsim.capture import full_spec, sequences_of
from tests.indepsim.sensor import SensorModel, SensorSpec


def test_col_fpn_excess_spread_over_frame_subsets_is_that_of_white_noise():
    case = next(c for c in CASES if c["name"] == "alone_adc_dnl")
    spec = full_spec(case_spec(case, None))
    sensor = SensorSpec(**spec["sensor"])
    model = SensorModel(sensor, spec["effects"], case["seed"])
    si, s = next((i, s) for i, s in enumerate(sequences_of(spec, sensor))
                 if s["kind"] == "dark" and s["iso"] == 100 and s["exposure_s"] < 0.1)
    x = np.stack([model.frame("dark", 100, s["exposure_s"], 0.0, np.random.default_rng([case["seed"], 4, si, i]), i, 16)
                  for i in range(16)]).astype(np.float32)
    black = np.full((2, 2), float(sensor.black_dn))
    rng = np.random.default_rng(0)
    vals = np.array([dg.col_fpn_excess(dg.CaptureData([x[rng.permutation(16)[:8]]], [], [], black, 4095.0, "RGGB"))
                     for _ in range(24)])
    white = 1.0 / np.sqrt(x.shape[2])
    # subsets share frames, so their spread is at most the independent draws' (the previous centring: 2.1)
    assert vals.std() < 2.0 * white and abs(vals.mean()) < 3 * white
