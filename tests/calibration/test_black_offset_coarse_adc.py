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


def _split_darks(edge: float, black_true: float = BLACK, step: float = 11.0, read: float = 1.0, seed: int = 1):
    """Darks through an ADC of ``step``-DN codes (multiples of ``step``) whose transition between the two
    codes around the black lies at ``edge`` DN (ideal: half-way), all other transitions ideal."""
    rng = np.random.default_rng(seed)
    v = black_true + rng.normal(0.0, read, (16, 32, 48))
    lo = np.floor(edge / step) * step  # the code below the displaced transition
    codes = np.where(v < edge, lo, lo + step)
    far = (v < lo - step / 2) | (v >= lo + 1.5 * step)
    codes = np.where(far, np.round(v / step) * step, codes).astype(np.float32)
    return dg.CaptureData([codes], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def test_darks_split_between_the_blacks_code_and_the_next_have_no_offset():
    """The transition between codes 253 and 264 at 255.5 DN instead of 258.5 puts about 70 % of a 256-DN
    black's darks on 264: a median 8 DN above the black, which a black 3 DN high would give as well. The
    split tells the transition's place, not the black's: no offset, with the reason."""
    card = CARDS["black_level_offset"]
    d = _split_darks(255.5)
    share = float(np.mean(d.darks[0] == 264.0))
    assert 0.6 < share < 0.8 and set(np.unique(d.darks[0]).tolist()) == {253.0, 264.0}
    for step in (None, 11.0):
        p = card.fit(d, _model(step), FitContext())
        assert card.is_null(p) and p.split_codes_dn == 11.0
        assert "transition" in card.null_reason(p)


def test_an_offset_beyond_the_next_code_is_still_measured():
    """Darks of a black 20 DN high (276: codes 275 and 264/286) do not sit on the black's code: measured."""
    card = CARDS["black_level_offset"]
    d = _split_darks(280.5, black_true=BLACK + 20.0)
    p = card.fit(d, _model(11.0), FitContext())
    assert not card.is_null(p) and p.split_codes_dn is None
    assert all(abs(x - 22.0) <= 11.0 for x in p.offset_dn)  # 275 against the black's code 253


def test_values_off_a_code_lattice_are_not_gated():
    """Float darks (a 0.3-DN read noise, no ADC codes) 0.4 DN above the black: an offset, measured."""
    card = CARDS["black_level_offset"]
    rng = np.random.default_rng(2)
    v = (BLACK + 0.4 + rng.normal(0.0, 0.3, (16, 32, 48))).astype(np.float32)
    p = card.fit(dg.CaptureData([v], [], [], np.full((2, 2), BLACK), 4095.0, "RGGB"), _model(None), FitContext())
    assert p.split_codes_dn is None and all(abs(x - 0.4) < 0.05 for x in p.offset_dn)
