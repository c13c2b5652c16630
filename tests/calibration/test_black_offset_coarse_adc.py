"""The black-level offset under a coarse ADC: darks that sit on the code the declared black reads as have
no offset. Made with numpy: a 256-DN black, 0.6-DN read noise, codes 14 DN apart (multiples of 14), so
every dark value is 252 -- the quantiser's, not a black level 4 DN low. An independent simulator's
quantisation set once got a ``black_level_offset`` of -4 DN beside its ``quantization`` this way."""

import numpy as np

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, FitContext
from simcam.calibration.model import LoopModel

BLACK, STEP, READ = 256.0, 14.0, 0.6


def _darks(black_true: float, seed: int = 0) -> dg.CaptureData:
    rng = np.random.default_rng(seed)
    v = black_true + rng.normal(0.0, READ, (16, 32, 48))
    codes = (np.round(v / STEP) * STEP).astype(np.float32)
    return dg.CaptureData([codes], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def _model(step: float | None) -> LoopModel:
    m = LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, 0.0, READ, READ ** 2)
    return m.with_effect("quantization", {"step_dn": step}) if step else m


def test_darks_on_the_declared_blacks_code_have_no_offset():
    card = CARDS["black_level_offset"]
    d = _darks(BLACK)
    assert set(np.unique(d.darks[0]).tolist()) == {252.0}
    p = card.fit(d, _model(STEP), FitContext())
    assert p.offset_dn == [0.0] * 4 and card.is_null(p)
    # with a 1-DN ADC in the model the 4 DN are an offset (the model would put the darks at 256)
    assert card.fit(d, _model(None), FitContext()).offset_dn == [-4.0] * 4


def test_an_offset_of_a_code_or_more_is_measured_in_codes():
    card = CARDS["black_level_offset"]
    d = _darks(BLACK + 11.0)  # 267 reads as 266, the next code up
    p = card.fit(d, _model(STEP), FitContext())
    assert p.offset_dn == [14.0] * 4 and not card.is_null(p)
